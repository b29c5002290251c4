//! The committed soundboard asset is what its generator makes, and it has the physics it claims.

use std::f64::consts::PI;
use unacorda::engine::plate::{generate_asset, PlateParams};
use unacorda::engine::soundboard::SoundboardModes;

const ASSET: &str = "assets/soundboard_modes/plate_ss.txt";
const COMMAND: &str =
    "cargo run --release -- soundboard --out assets/soundboard_modes/plate_ss.txt";

#[test]
fn committed_asset_equals_a_fresh_generation() {
    let committed =
        std::fs::read_to_string(format!("{}/{ASSET}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let (reduced, fresh) = generate_asset(&PlateParams::default(), COMMAND);
    println!(
        "{ASSET}: {} modes, {} bytes; fresh generation identical: {}",
        reduced.len(),
        fresh.len(),
        fresh == committed
    );
    assert!(fresh == committed, "regenerate with: {COMMAND}");
}

#[test]
fn plate_modes_follow_the_closed_form_and_the_modal_density() {
    let p = PlateParams::default();
    let full = p.all_modes();
    let (d1, d2, _) = p.rigidities();
    let rho_h = p.density_kg_m3 * p.thickness_m;
    let area = p.width_m * p.length_m;
    // Asymptotic modal density of an orthotropic plate: n = S/2 sqrt(rho h / sqrt(D1 D2)) per Hz.
    let density = area / 2.0 * (rho_h / (d1 * d2).sqrt()).sqrt();
    let expected = density * p.f_max_hz;
    let count = full.modes.len() as f64;
    println!(
        "plate modes below {} Hz: {count} (asymptotic {expected:.0}, {:+.1} %)",
        p.f_max_hz,
        100.0 * (count / expected - 1.0)
    );
    assert!((count / expected - 1.0).abs() < 0.25);
    // Mass normalisation: rho h ∫ w^2 dA = 1 for the mode shapes, by quadrature.
    let (m, n) = full.index[5];
    let amp = 2.0 / (rho_h * area).sqrt();
    let k = 400;
    let mut mass = 0.0;
    for i in 0..k {
        for j in 0..k {
            let x = (i as f64 + 0.5) / k as f64 * p.width_m;
            let y = (j as f64 + 0.5) / k as f64 * p.length_m;
            let w = amp
                * (m as f64 * PI * x / p.width_m).sin()
                * (n as f64 * PI * y / p.length_m).sin();
            mass += rho_h * w * w * area / (k * k) as f64;
        }
    }
    println!("mode ({m},{n}): modal mass {mass:.12}");
    assert!((mass - 1.0).abs() < 1e-9);
}

#[test]
fn reduced_board_has_a_piano_like_mobility() {
    let text = std::fs::read_to_string(format!("{}/{ASSET}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let board = SoundboardModes::parse(&text, ASSET.as_ref()).unwrap();
    let c2 = board.point("C2").unwrap();
    println!(
        "reduced board: {} modes, {:.1}–{:.1} Hz",
        board.len(),
        board.freq_hz[0],
        board.freq_hz[board.len() - 1]
    );
    println!("  f (Hz)   |Y_TT| m/(N s)   |Y_LL|      |Y_PP|      |Y_TL|/|Y_LT|");
    for f in [50.0, 100.0, 200.0, 500.0, 1000.0, 3000.0] {
        let y = board.mobility(c2, 2.0 * PI * f);
        let mag = |i: usize, j: usize| (y[i][j][0].powi(2) + y[i][j][1].powi(2)).sqrt();
        println!(
            "  {f:6.0} {:14.3e} {:11.3e} {:11.3e} {:9.6}",
            mag(0, 0),
            mag(1, 1),
            mag(2, 2),
            mag(0, 1) / mag(1, 0)
        );
        assert!(
            (mag(0, 1) - mag(1, 0)).abs() <= 1e-12 * mag(0, 1),
            "reciprocity"
        );
    }
    let y100 = board.mobility(c2, 2.0 * PI * 100.0);
    let tt = (y100[0][0][0].powi(2) + y100[0][0][1].powi(2)).sqrt();
    assert!(
        (1e-4..1e-2).contains(&tt),
        "measured grand-piano range near 100 Hz"
    );
}
