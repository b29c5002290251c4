//! What the plugin's tests compare its sound with: the offline render of the same events on the
//! concert keyboard (`render --offline --midi`'s path, one core), and the comparison, bit for bit.

use unacorda::engine::VoicePool;
use unacorda::midi::file::TimedEvent;
use unacorda::midi::{Event, Pedal};
use unacorda_clap::params::{PARAMS, SOFT, SOSTENUTO, SUSTAIN};

/// What the piano plays for a host's change of the parameter with id `id` to `value`: a pedal's
/// depth (the plugin plays it so), or nothing for the other parameters.
pub fn pedal_of_param(id: u32, value: f64) -> Option<Event> {
    let pedals = [
        (SUSTAIN, Pedal::Sustain),
        (SOSTENUTO, Pedal::Sostenuto),
        (SOFT, Pedal::Soft),
    ];
    let (_, pedal) = pedals.into_iter().find(|&(i, _)| PARAMS[i].id == id)?;
    Some(Event::Pedal {
        pedal,
        depth: value,
    })
}

/// The offline render of `events` on the engine `E`, with the pedal's halo or not: both
/// channels.
pub fn offline<E: VoicePool>(events: &[TimedEvent], tail_s: f64, halo: bool) -> [Vec<f32>; 2] {
    let scaling = unacorda::config::scaling::Scaling::resolve("concert").unwrap();
    let cache = unacorda::keycache::KeyCache::from_env();
    let keyboard = unacorda::play::Keyboard {
        scaling: &scaling,
        cache: cache.as_ref(),
    };
    let offline = unacorda::render::Offline {
        tail_s,
        voices: unacorda::play::DEFAULT_VOICES,
        cores: 1,
        halo,
    };
    let r =
        unacorda::render::render_midi_kept::<E>(keyboard, events, offline, |_| {}, None).unwrap();
    assert_eq!(r.channels, 2);
    [
        r.samples.iter().step_by(2).copied().collect(),
        r.samples.iter().skip(1).step_by(2).copied().collect(),
    ]
}

/// Both channels of what the plugin played, `latency` frames late, equal to the offline
/// render's bit for bit, and not silent.
pub fn equals_offline(engine: &str, heard: [&[f32]; 2], latency: usize, render: [&[f32]; 2]) {
    for (c, name) in ["left", "right"].iter().enumerate() {
        let differ = heard[c][latency..]
            .iter()
            .zip(render[c])
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        let peak = render[c].iter().fold(0f32, |m, s| m.max(s.abs()));
        println!(
            "{engine} {name}: {} frames, peak {peak:.3}, {differ} differ from the offline render",
            render[c].len()
        );
        assert!(peak > 0.01);
        assert_eq!(differ, 0, "{engine} {name} differs from the offline render");
    }
}
