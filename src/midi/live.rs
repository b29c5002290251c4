//! The MIDI byte-stream parser used for live input: whatever the port delivers, in whatever
//! pieces, comes out as piano events. It follows the MIDI 1.0 byte grammar: running status,
//! real-time bytes (0xF8–0xFF) allowed anywhere (even inside another message) and ignored, SysEx
//! (0xF0 … 0xF7) skipped, system common messages (0xF1–0xF7, the end of a SysEx among them)
//! skipped with their data and clearing running status, and data bytes without a status dropped. It never allocates, so it can run on
//! the audio thread.

use super::{Decoder, Event};

/// Streaming parser state.
#[derive(Debug, Clone, Default)]
pub struct LiveParser {
    running_status: Option<u8>,
    data: [u8; 2],
    filled: usize,
    in_sysex: bool,
    /// Data bytes still to skip of a system common message.
    skip: usize,
    decoder: Decoder,
}

/// Data bytes that follow a channel status.
fn data_len(status: u8) -> usize {
    match status & 0xF0 {
        0xC0 | 0xD0 => 1,
        _ => 2,
    }
}

impl LiveParser {
    pub fn new() -> Self {
        Self::default()
    }

    /// Feed one byte; returns the piano event it completes, if any.
    pub fn push(&mut self, byte: u8) -> Option<Event> {
        match byte {
            0xF8..=0xFF => None, // real time: transparent
            0xF0 => {
                self.in_sysex = true;
                self.running_status = None;
                None
            }
            0xF1..=0xF7 => {
                self.in_sysex = false;
                self.running_status = None;
                self.skip = match byte {
                    0xF1 | 0xF3 => 1,
                    0xF2 => 2,
                    _ => 0,
                };
                None
            }
            0x80..=0xEF => {
                self.in_sysex = false;
                self.skip = 0;
                self.running_status = Some(byte);
                self.filled = 0;
                None
            }
            _ => {
                if self.in_sysex {
                    return None;
                }
                if self.skip > 0 {
                    self.skip -= 1;
                    return None;
                }
                let status = self.running_status?;
                self.data[self.filled] = byte;
                self.filled += 1;
                if self.filled < data_len(status) {
                    return None;
                }
                self.filled = 0;
                self.decoder.decode(status, self.data[0], self.data[1])
            }
        }
    }

    /// Feed a buffer, handing each completed event to `sink`.
    pub fn feed(&mut self, bytes: &[u8], mut sink: impl FnMut(Event)) {
        for &b in bytes {
            if let Some(e) = self.push(b) {
                sink(e);
            }
        }
    }
}
