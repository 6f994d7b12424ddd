//! The one stream of pictures handed to every consumer in the vehicle (the
//! WebRTC viewers' hub, the recorder), whatever route made it: our
//! encoder's RTP read back and put together once (`depay`), or a camera's
//! own H.264 as the relay cut it.
//!
//! Each consumer has a bounded queue. One that falls behind (its queue is
//! full) gets nothing until the next keyframe, so it never receives a
//! picture it cannot decode, and never holds up the others or the RTP to
//! ground stations. A consumer gets its first picture at a keyframe too.
//! One that is gone is forgotten.

use tokio::sync::mpsc;

use crate::camera::h264::AccessUnit;

/// One consumer's queue.
#[derive(Debug)]
struct Sink {
    tx: mpsc::Sender<AccessUnit>,
    /// Nothing goes to it until a keyframe: at the start, after a miss.
    needs_keyframe: bool,
}

/// Pictures out to every consumer.
#[derive(Debug, Default)]
pub(super) struct Fanout {
    sinks: Vec<Sink>,
    /// Pictures a consumer missed (its queue was full).
    pub missed: u64,
}

impl Fanout {
    pub fn new(consumers: &[mpsc::Sender<AccessUnit>]) -> Self {
        Fanout {
            sinks: consumers
                .iter()
                .map(|tx| Sink {
                    tx: tx.clone(),
                    needs_keyframe: true,
                })
                .collect(),
            missed: 0,
        }
    }

    /// One picture to every consumer that can take it.
    pub fn send(&mut self, au: &AccessUnit) {
        let mut missed = 0;
        self.sinks.retain_mut(|s| {
            if s.needs_keyframe && !au.keyframe {
                return true;
            }
            match s.tx.try_send(au.clone()) {
                Ok(()) => {
                    s.needs_keyframe = false;
                    true
                }
                Err(mpsc::error::TrySendError::Full(_)) => {
                    missed += 1;
                    s.needs_keyframe = true;
                    true
                }
                Err(mpsc::error::TrySendError::Closed(_)) => false,
            }
        });
        self.missed += missed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn au(n: u8, keyframe: bool) -> AccessUnit {
        AccessUnit {
            data: vec![0, 0, 0, 1, if keyframe { 0x65 } else { 0x41 }, n],
            time_90khz: u64::from(n) * 3000,
            keyframe,
        }
    }

    fn drain(rx: &mut mpsc::Receiver<AccessUnit>) -> Vec<u8> {
        let mut got = Vec::new();
        while let Ok(a) = rx.try_recv() {
            got.push(a.data[5]);
        }
        got
    }

    #[test]
    fn every_consumer_gets_each_picture_from_a_keyframe_on() {
        let (a_tx, mut a) = mpsc::channel(8);
        let (b_tx, mut b) = mpsc::channel(8);
        let mut f = Fanout::new(&[a_tx, b_tx]);
        for p in [au(1, false), au(2, true), au(3, false), au(4, false)] {
            f.send(&p);
        }
        assert_eq!(drain(&mut a), [2, 3, 4]);
        assert_eq!(drain(&mut b), [2, 3, 4]);
        assert_eq!(f.missed, 0);
    }

    #[test]
    fn a_slow_consumer_skips_to_the_next_keyframe_and_holds_up_no_other() {
        let (slow_tx, mut slow) = mpsc::channel(2);
        let (fast_tx, mut fast) = mpsc::channel(16);
        let mut f = Fanout::new(&[slow_tx, fast_tx]);
        for p in [au(1, true), au(2, false), au(3, false), au(4, false)] {
            f.send(&p);
        }
        // The slow one took two, missed the third, and the fourth (not a
        // keyframe) is held back: it could not decode it.
        assert_eq!(drain(&mut slow), [1, 2]);
        assert_eq!(f.missed, 1);
        f.send(&au(5, false));
        f.send(&au(6, true));
        f.send(&au(7, false));
        assert_eq!(drain(&mut slow), [6, 7]);
        assert_eq!(drain(&mut fast), [1, 2, 3, 4, 5, 6, 7]);
    }

    #[test]
    fn a_consumer_that_is_gone_is_forgotten() {
        let (gone_tx, gone) = mpsc::channel(2);
        let (ok_tx, mut ok) = mpsc::channel(2);
        drop(gone);
        let mut f = Fanout::new(&[gone_tx, ok_tx]);
        f.send(&au(1, true));
        assert_eq!(f.sinks.len(), 1);
        assert_eq!(drain(&mut ok), [1]);
    }
}
