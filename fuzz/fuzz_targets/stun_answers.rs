//! Fuzzes the STUN reader (the vehicle's public address, asked of STUN
//! servers): any datagram must never panic; what it accepts must be a
//! binding success answer of exactly its declared length, whose transaction
//! is the header's; an answer written from what was read reads the same;
//! and an answer built from the input (its bytes as the transaction, the
//! address and other attributes before XOR-MAPPED-ADDRESS) reads back to
//! exactly that transaction and address. Our own request is never an answer.
#![no_main]

use std::net::{IpAddr, SocketAddr};

use libfuzzer_sys::fuzz_target;
use neptunus::fuzzing::{binding_request, parse_binding_success, stun_binding_success};

const XOR_MAPPED_ADDRESS: u16 = 0x0020;

fuzz_target!(|data: &[u8]| {
    // The input as a datagram.
    if let Some((id, addr)) = parse_binding_success(data) {
        assert_eq!(data[..2], [0x01, 0x01], "not a binding success");
        assert_eq!(data[4..8], [0x21, 0x12, 0xa4, 0x42], "no magic cookie");
        assert_eq!(
            data.len(),
            20 + usize::from(u16::from_be_bytes([data[2], data[3]]))
        );
        assert_eq!(id[..], data[8..20]);
        let again = stun_binding_success(id, addr, &[]);
        assert_eq!(parse_binding_success(&again), Some((id, addr)));
    }

    // The input as the parts of an answer.
    let Some((id, rest)) = data.split_first_chunk::<12>() else {
        return;
    };
    assert_eq!(parse_binding_success(&binding_request(*id)), None);
    let Some((&[family, p0, p1], rest)) = rest.split_first_chunk::<3>() else {
        return;
    };
    let (ip, mut rest): (IpAddr, &[u8]) = if family & 1 == 0 {
        let Some((a, r)) = rest.split_first_chunk::<4>() else {
            return;
        };
        ((*a).into(), r)
    } else {
        let Some((a, r)) = rest.split_first_chunk::<16>() else {
            return;
        };
        ((*a).into(), r)
    };
    let addr = SocketAddr::new(ip, u16::from_be_bytes([p0, p1]));
    // Other attributes: type (2 bytes), length (1 byte), value.
    let mut before = Vec::new();
    while let Some((&[t0, t1, n], r)) = rest.split_first_chunk::<3>() {
        let kind = u16::from_be_bytes([t0, t1]);
        let n = usize::from(n).min(r.len());
        if kind != XOR_MAPPED_ADDRESS {
            before.push((kind, r[..n].to_vec()));
        }
        rest = &r[n..];
    }
    let answer = stun_binding_success(*id, addr, &before);
    assert_eq!(parse_binding_success(&answer), Some((*id, addr)));
    // Cut short, or one byte too long, it is no answer.
    assert_eq!(parse_binding_success(&answer[..answer.len() - 1]), None);
    let mut long = answer.clone();
    long.push(0);
    assert_eq!(parse_binding_success(&long), None);
});
