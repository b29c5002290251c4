//! WAV output (32-bit float, mono or stereo) through hound, streamed block by block so that a long render
//! never holds its sound in memory and an interrupted or failed one leaves a valid file.
//!
//! The header is brought up to date every second of sound (hound's `flush`), and when a write
//! fails (disk full, file-size limit) the file is cut back to its last whole frame and its
//! header rewritten in place — which needs no new space — so what reached the disk stays playable.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

type Writer = hound::WavWriter<BufWriter<File>>;

/// Why a WAV could not be written (or not completely).
#[derive(Debug, thiserror::Error)]
pub enum WavError {
    #[error("{}: cannot create the WAV", path.display())]
    Create {
        path: PathBuf,
        #[source]
        source: hound::Error,
    },
    #[error("{}: writing stopped after {written_s:.2} s of sound; the file holds the first {kept_s:.2} s as a valid WAV", path.display())]
    Write {
        path: PathBuf,
        written_s: f64,
        kept_s: f64,
        #[source]
        source: hound::Error,
    },
    #[error("{}: a WAV holds at most {max_s:.0} s at this rate (4 GiB of samples); render less (--max-seconds)", path.display())]
    TooLong { path: PathBuf, max_s: f64 },
    #[error("{}: writing stopped after {written_s:.2} s of sound; the file could not be repaired ({repair}) and is not a valid WAV", path.display())]
    Unrepaired {
        path: PathBuf,
        written_s: f64,
        #[source]
        source: hound::Error,
        repair: io::Error,
    },
}

/// A 32-bit float WAV being written, its channels interleaved.
pub struct WavStream {
    writer: Option<Writer>,
    path: PathBuf,
    rate_hz: u32,
    channels: u16,
    samples: u64,
    since_checkpoint: u64,
}

/// Bytes per sample: 32-bit float.
const SAMPLE_BYTES: u64 = 4;

/// Samples a WAV can hold: its sizes are 32-bit (less the header's share).
const MAX_SAMPLES: u64 = (u32::MAX as u64 - 1024) / SAMPLE_BYTES;

impl WavStream {
    /// Create (or truncate) `path` for sound at `rate_hz` in `channels` channels (1 or 2).
    pub fn create(path: &Path, rate_hz: u32, channels: u16) -> Result<WavStream, WavError> {
        let spec = hound::WavSpec {
            channels,
            sample_rate: rate_hz,
            bits_per_sample: 32,
            sample_format: hound::SampleFormat::Float,
        };
        let writer = hound::WavWriter::create(path, spec).map_err(|source| WavError::Create {
            path: path.to_owned(),
            source,
        })?;
        Ok(WavStream {
            writer: Some(writer),
            path: path.to_owned(),
            rate_hz,
            channels,
            samples: 0,
            since_checkpoint: 0,
        })
    }

    /// Append `samples` (full scale ±1, whole frames of interleaved channels). On failure the file is repaired to what reached the disk
    /// and the error says how much that is; the stream accepts nothing more.
    pub fn write(&mut self, samples: &[f32]) -> Result<(), WavError> {
        let Some(w) = self.writer.as_mut() else {
            return Ok(());
        };
        if self.samples + samples.len() as u64 > MAX_SAMPLES {
            return Err(WavError::TooLong {
                path: self.path.clone(),
                max_s: MAX_SAMPLES as f64 / self.samples_per_s(),
            });
        }
        let mut result = samples.iter().try_for_each(|&s| w.write_sample(s));
        self.samples += samples.len() as u64;
        self.since_checkpoint += samples.len() as u64;
        let second = u64::from(self.rate_hz) * u64::from(self.channels);
        if result.is_ok() && self.since_checkpoint >= second {
            self.since_checkpoint = 0;
            result = w.flush();
        }
        result.map_err(|e| self.fail(e))
    }

    /// Seconds of sound handed to the stream so far.
    pub fn written_s(&self) -> f64 {
        self.samples as f64 / self.samples_per_s()
    }

    fn samples_per_s(&self) -> f64 {
        f64::from(self.rate_hz) * f64::from(self.channels)
    }

    /// Write the final header; returns the seconds written.
    pub fn finish(mut self) -> Result<f64, WavError> {
        match self.writer.take() {
            Some(w) => match w.finalize() {
                Ok(()) => Ok(self.written_s()),
                Err(e) => Err(self.fail(e)),
            },
            None => Ok(self.written_s()),
        }
    }

    /// Close the writer after `source` and make the file valid up to its last whole sample.
    fn fail(&mut self, source: hound::Error) -> WavError {
        // Dropping hound's writer tries to finalise; whatever it manages, the repair below sets
        // the header from the file's real length.
        drop(self.writer.take());
        let (path, written_s) = (self.path.clone(), self.written_s());
        match repair(&self.path, self.channels) {
            Ok(frames) => WavError::Write {
                path,
                written_s,
                kept_s: frames as f64 / f64::from(self.rate_hz),
                source,
            },
            Err(repair) => WavError::Unrepaired {
                path,
                written_s,
                source,
                repair,
            },
        }
    }
}

/// Cut a WAV written by [`WavStream`] back to its last whole frame and set the RIFF and data sizes
/// from that length, in place (the header exists: hound writes it when the file is created).
/// Returns the frames (of `channels` samples) the file holds.
fn repair(path: &Path, channels: u16) -> io::Result<u64> {
    let mut file = OpenOptions::new().read(true).write(true).open(path)?;
    let len = file.metadata()?.len();
    let mut head = [0u8; 128];
    let n = file.read(&mut head)?;
    let bad = || io::Error::new(io::ErrorKind::InvalidData, "no RIFF/WAVE header to repair");
    if n < 12 || &head[..4] != b"RIFF" || &head[8..12] != b"WAVE" {
        return Err(bad());
    }
    // Walk the chunks to the data chunk's header.
    let mut at = 12usize;
    let data_start = loop {
        if at + 8 > n {
            return Err(bad());
        }
        let size = u32::from_le_bytes(head[at + 4..at + 8].try_into().expect("4 bytes"));
        if &head[at..at + 4] == b"data" {
            break (at + 8) as u64;
        }
        at += 8 + size as usize;
    };
    let frame_bytes = SAMPLE_BYTES * u64::from(channels.max(1));
    let frames = len.saturating_sub(data_start) / frame_bytes;
    let data_bytes = frames * frame_bytes;
    file.set_len(data_start + data_bytes)?;
    let riff = u32::try_from(data_start + data_bytes - 8).map_err(|_| bad())?;
    file.seek(SeekFrom::Start(4))?;
    file.write_all(&riff.to_le_bytes())?;
    file.seek(SeekFrom::Start(data_start - 4))?;
    file.write_all(&(data_bytes as u32).to_le_bytes())?;
    file.sync_all()?;
    Ok(frames)
}

/// Write `samples` (full scale ±1, `channels` interleaved) as a 32-bit float WAV at `rate_hz`;
/// returns the seconds.
pub fn write_f32(
    path: &Path,
    rate_hz: u32,
    channels: u16,
    samples: &[f32],
) -> Result<f64, WavError> {
    let mut w = WavStream::create(path, rate_hz, channels)?;
    for block in samples.chunks(4096 * usize::from(channels.max(1))) {
        w.write(block)?;
    }
    w.finish()
}
