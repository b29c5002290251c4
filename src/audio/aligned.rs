//! A host's blocks of any length played on the synth's grid ([`ALIGN_FRAMES`]): the synth renders
//! whole cells of the grid, one cell behind the host, so that however a host cuts time into
//! blocks (1 to 4096 frames, changing from block to block), every sample is the one an offline
//! render gives, delayed by [`LATENCY_FRAMES`] (0.67 ms at 48 kHz), which the host is told and
//! compensates. Events are scheduled at the host's next frame; a cell is rendered only once every
//! event inside it is known. Never allocates after [`Aligned::new`].

use super::synth::{Scheduled, Synth, SynthHandle, ALIGN_FRAMES};
use crate::engine::{Pair, VoicePool};
use crate::midi::Event;
use std::sync::atomic::Ordering;

/// How far the output lags the events: one cell of the grid.
pub const LATENCY_FRAMES: u64 = ALIGN_FRAMES;

/// A synth driven by a host's blocks (touched by the audio thread only).
pub struct Aligned<E: VoicePool> {
    synth: Synth<E>,
    /// The synth's handle: its event queue and counters.
    handle: SynthHandle<E>,
    channels: usize,
    /// The last cell rendered (interleaved), and how many of its frames the host has taken;
    /// before the first cell, a cell of silence (the latency).
    cell: Vec<f32>,
    taken: usize,
    /// Output frames handed to the host so far.
    handed: u64,
}

impl<E: VoicePool> Aligned<E> {
    /// Play `synth` in `channels` interleaved channels, its events through its `handle`.
    pub fn new(synth: Synth<E>, handle: SynthHandle<E>, channels: usize) -> Self {
        let channels = channels.max(1);
        Aligned {
            synth,
            handle,
            channels,
            cell: vec![0.0; ALIGN_FRAMES as usize * channels],
            taken: 0,
            handed: 0,
        }
    }

    /// The synth (its piano, its clock).
    pub fn synth(&self) -> &Synth<E> {
        &self.synth
    }

    /// Channels of the interleaved frames it hands out.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Play `event` at the next frame the host will be handed (heard [`LATENCY_FRAMES`] later).
    /// When the queue is full (thousands of events inside one cell) a release waits and is
    /// queued with the next cell, a strike is dropped ([`SynthHandle::schedule_live`]), and
    /// either is counted in [`Stats::late_events`]; returns whether it was queued now.
    pub fn schedule(&mut self, event: Event) -> bool {
        let dropped = self.handle.backlog.dropped_note_ons;
        self.handle.schedule_live(Scheduled {
            frame: self.handed,
            event,
        });
        let backlog = &self.handle.backlog;
        let queued = backlog.is_empty() && backlog.dropped_note_ons == dropped;
        if !queued {
            self.handle
                .stats
                .late_events
                .fetch_add(1, Ordering::Relaxed);
        }
        queued
    }

    /// Fill `out` (interleaved, the channels of [`Aligned::new`]) with the next frames.
    pub fn process(&mut self, out: &mut [f32]) {
        self.process_on(out, None);
    }

    /// [`Aligned::process`] with `pair` lending the engine a second core ([`Synth::process_on`]).
    pub fn process_on(&mut self, out: &mut [f32], pair: Option<&dyn Pair>) {
        let ch = self.channels;
        let cell_frames = ALIGN_FRAMES as usize;
        let whole = out.len() / ch * ch;
        let mut out = &mut out[..whole];
        while !out.is_empty() {
            if self.taken == cell_frames {
                // Releases a full queue kept, queued before the cell is rendered.
                self.handle.flush_backlog(self.handed);
                // Every event up to this cell's end has been scheduled: its last frame is the
                // frame the host is handed now, less the latency.
                self.synth.process_on(&mut self.cell, ch, pair);
                self.taken = 0;
            }
            let n = (cell_frames - self.taken).min(out.len() / ch);
            let (head, rest) = std::mem::take(&mut out).split_at_mut(n * ch);
            head.copy_from_slice(&self.cell[self.taken * ch..(self.taken + n) * ch]);
            self.taken += n;
            self.handed += n as u64;
            out = rest;
        }
    }

    /// Whether the output is silent from here on until the next event: no voice sounds, no event
    /// is waiting and the cell being handed out is below the 24-bit floor.
    pub fn is_silent(&self) -> bool {
        let floor = f32::EPSILON;
        self.cell.iter().all(|s| s.abs() < floor)
            && self.synth.is_quiet()
            && self.handle.backlog.is_empty()
    }

    /// Silence every voice at once (a host's reset): keys up, pedals up, strings and board at
    /// rest, the queued events dropped and the cell cleared.
    pub fn silence(&mut self) {
        self.synth.silence();
        self.cell.fill(0.0);
    }
}
