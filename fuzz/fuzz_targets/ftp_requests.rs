//! Fuzzes MAVLink FTP requests: any 251-byte payloads must parse without a
//! panic; a path names something in the tree only through admitted names
//! (no `..`, no separator, nothing hidden); and the vehicle core, given a
//! run of such requests from two stations (the disk answering "not
//! found"), answers each request that is not a burst with exactly one
//! reply to its sender, never writes, and moves no thruster.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::dialect::neptunus::{FILE_TRANSFER_PROTOCOL_DATA, MavMessage};
use neptunus::files::tree::{self, Node};
use neptunus::files::{FileAnswer, FileError, FileOp, FileReply};
use neptunus::mavlink::ftp::{self, PAYLOAD_LEN, Request, op};
use neptunus::vehicle::machine::{Identity, Input, NEUTRAL_US, Now, Output, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

fn check_path(path: &[u8]) {
    if let Some(Node::Disk(p)) = tree::resolve(path) {
        for part in &p.parts {
            assert!(tree::safe_name(part), "{part:?}");
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let stations = [Sender::new(0, 1, 255, 190), Sender::new(0, 2, 77, 190)];
    let mut v = Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1);
    let mut t = std::time::Duration::ZERO;
    for (i, chunk) in data.chunks(PAYLOAD_LEN).enumerate() {
        let mut payload = [0u8; PAYLOAD_LEN];
        payload[..chunk.len()].copy_from_slice(chunk);
        let (h, request) = ftp::parse(&payload);
        if let Ok(
            Request::ListDirectory { path, .. }
            | Request::OpenFileRO { path }
            | Request::CalcFileCRC32 { path },
        ) = request
        {
            check_path(path);
        }
        let from = stations[i % 2];
        t += std::time::Duration::from_millis(3);
        let now = Now {
            mono: t,
            unix_us: 1_800_000_000_000_000,
        };
        let mut out = Vec::new();
        v.handle(
            Input::Mavlink {
                from,
                msg: MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                    target_network: 0,
                    target_system: 1,
                    target_component: 1,
                    payload,
                }),
            },
            now,
            &mut out,
        );
        // The disk finds nothing (the tree's folders are empty).
        let mut replies = 0;
        let mut pending = out;
        while !pending.is_empty() {
            let mut next = Vec::new();
            for o in pending {
                match o {
                    Output::Files(req) => {
                        let result = match req.op {
                            FileOp::List(_) => Ok(FileAnswer::Listing(Vec::new())),
                            FileOp::EraseLogs => panic!("an FTP request erased logs"),
                            _ => Err(FileError::NotFound),
                        };
                        v.handle(
                            Input::Files(FileReply {
                                token: req.token,
                                result,
                            }),
                            now,
                            &mut next,
                        );
                    }
                    Output::Bulk { to, msg } => {
                        assert_eq!(to, To::Peer(from.endpoint, from.peer));
                        let MavMessage::FILE_TRANSFER_PROTOCOL(r) = msg else {
                            panic!("a reply that is not FTP");
                        };
                        assert_eq!((r.target_system, r.target_component), (from.sysid, from.compid));
                        replies += 1;
                    }
                    Output::Board(neptunus::firmware::codec::Command::Go {
                        port_us,
                        vertical_us,
                        starboard_us,
                    }) => {
                        assert_eq!([port_us, vertical_us, starboard_us], [NEUTRAL_US; 3]);
                    }
                    _ => {}
                }
            }
            pending = next;
        }
        if h.opcode != op::BURST_READ_FILE {
            assert_eq!(replies, 1, "request {h:?}");
        }
        // Bursts send on the transfers' passes.
        let mut passes = 0;
        while let Some(due) = v.next_transfer() {
            t = t.max(due);
            let mut out = Vec::new();
            v.handle(
                Input::Transfer,
                Now {
                    mono: t,
                    unix_us: 1_800_000_000_000_000,
                },
                &mut out,
            );
            passes += 1;
            if passes > 10_000 {
                panic!("a burst that never ends");
            }
        }
    }
});
