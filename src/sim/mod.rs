//! Vehicle simulator (in progress).
