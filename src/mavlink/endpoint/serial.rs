//! Serial endpoints (`serial:PATH[:BAUD]`): opening the port 8N1 without
//! flow control, as telemetry radios and USB adapters expect. The open port
//! is one byte-stream peer, kept open by
//! [`run_connector`](super::stream::run_connector) like a `tcpout` link.
//!
//! It must never take the port exclusively: a technician may want to sniff
//! the radio link.

use std::io;

pub(super) fn open_serial(
    path: &std::path::Path,
    baud: u32,
) -> io::Result<tokio_serial::SerialStream> {
    use tokio_serial::SerialPortBuilderExt;
    let mut port = tokio_serial::new(path.to_string_lossy(), baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(io::Error::from)?;
    // Not exclusive: a technician may want to sniff the radio link; and on a
    // pty some ioctls are unsupported, which is harmless here.
    if let Err(e) = port.set_exclusive(false) {
        tracing::debug!(path = %path.display(), error = %e, "cannot clear exclusive mode");
    }
    Ok(port)
}
