//! The soundboard generator (issue 3): closed-form check, modal density, mass normalisation,
//! reciprocity, the reduced model against the full one, and the committed asset = a fresh run.

use std::f64::consts::PI;
use std::path::Path;
use unacorda::analysis::mobility::{band_levels_db, mobility_curves};
use unacorda::engine::plate::{generate_asset, BoardSpec, Edges};
use unacorda::engine::soundboard::SoundboardModes;
use unacorda::preset::{parse_board_spec, GRAND_BOARD_TOML};

const ASSET: &str = "assets/soundboard_modes/grand.txt";
const COMMAND: &str =
    "cargo run --release -- soundboard --input assets/soundboard_modes/grand.toml --out assets/soundboard_modes/grand.txt";

fn grand() -> BoardSpec {
    parse_board_spec(
        GRAND_BOARD_TOML,
        Path::new("assets/soundboard_modes/grand.toml"),
    )
    .unwrap()
}

#[test]
fn committed_asset_equals_a_fresh_generation_and_the_board_checks_out() {
    let spec = grand();
    let (solved, reduced, fresh) = generate_asset(&spec, COMMAND).unwrap();
    let committed =
        std::fs::read_to_string(format!("{}/{ASSET}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    println!(
        "{ASSET}: {} of {} modes, {} bytes; fresh generation identical: {}",
        reduced.len(),
        solved.modes.len(),
        fresh.len(),
        fresh == committed
    );
    assert!(fresh == committed, "regenerate with: {COMMAND}");

    // Mode count against the plate's asymptotic modal density.
    let density = spec.plate.modal_density_per_hz();
    let expected = density * (spec.reduction.f_max_hz - spec.reduction.f_min_hz);
    let count = solved.modes.len() as f64;
    println!(
        "modes in {}–{} Hz: {count} (Ritz basis {}), plate asymptote {expected:.0} ({:+.1} %); first modes {:.1}, {:.1}, {:.1} Hz",
        spec.reduction.f_min_hz,
        spec.reduction.f_max_hz,
        solved.basis_size,
        100.0 * (count / expected - 1.0),
        solved.modes.freq_hz[0],
        solved.modes.freq_hz[1],
        solved.modes.freq_hz[2]
    );
    assert!((count / expected - 1.0).abs() < 0.25);

    // Mass normalisation cᵀ M c = 1 and M-orthogonality, from the Ritz matrices.
    let c = &solved.coefficients;
    let gram = c.transpose() * &solved.mass_matrix * c;
    let mut worst_diag: f64 = 0.0;
    let mut worst_off: f64 = 0.0;
    for i in 0..gram.nrows() {
        for j in 0..gram.ncols() {
            if i == j {
                worst_diag = worst_diag.max((gram[(i, j)] - 1.0).abs());
            } else {
                worst_off = worst_off.max(gram[(i, j)].abs());
            }
        }
    }
    println!("mass normalisation: max |cᵀMc − 1| = {worst_diag:.2e}, max |c_iᵀ M c_j| = {worst_off:.2e} (limit 1e-9)");
    assert!(worst_diag < 1e-9 && worst_off < 1e-9);

    // Reduced vs full driving-point mobility at C2, 1/3-octave band levels below 1 kHz.
    let full_c2 = solved.modes.point("C2").unwrap();
    let red_c2 = reduced.point("C2").unwrap();
    let curves_full = mobility_curves(&solved.modes, full_c2, 20.0, 7000.0, 800);
    let curves_red = mobility_curves(&reduced, red_c2, 20.0, 7000.0, 800);
    println!("C2 driving-point mobility, 1/3-octave band level of |Y| (dB re 1 m/(N s)), full vs reduced:");
    println!("  band Hz    TT full  TT red    LL full  LL red    PP full  PP red");
    let bands_full: Vec<Vec<(f64, f64)>> = (0..6)
        .map(|t| band_levels_db(&curves_full.freq_hz, &curves_full.magnitude[t]))
        .collect();
    let bands_red: Vec<Vec<(f64, f64)>> = (0..6)
        .map(|t| band_levels_db(&curves_red.freq_hz, &curves_red.magnitude[t]))
        .collect();
    let mut worst_tt: f64 = 0.0;
    for (b, &(fc, full_tt)) in bands_full[0].iter().enumerate() {
        let row = |t: usize| (bands_full[t][b].1, bands_red[t][b].1);
        let (ll, pp) = (row(3), row(5));
        println!(
            "  {fc:7.0} {full_tt:9.1} {:7.1} {:9.1} {:7.1} {:9.1} {:7.1}",
            bands_red[0][b].1, ll.0, ll.1, pp.0, pp.1
        );
        if fc < 1000.0 {
            worst_tt = worst_tt.max((full_tt - bands_red[0][b].1).abs());
        }
    }
    println!("  worst TT band difference below 1 kHz: {worst_tt:.2} dB (limit 3)");
    assert!(worst_tt < 3.0);
    // Reciprocity: the mobility matrix is symmetric.
    let y = reduced.mobility(red_c2, 2.0 * PI * 100.0);
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let (a, b) = (y[i][j], y[j][i]);
        assert!(
            (a[0] - b[0]).abs() <= 1e-15 * a[0].abs().max(1e-30)
                && (a[1] - b[1]).abs() <= 1e-15 * a[1].abs().max(1e-30)
        );
    }
    let tt100 = (y[0][0][0].powi(2) + y[0][0][1].powi(2)).sqrt();
    println!("|Y_TT| at 100 Hz, C2: {tt100:.2e} m/(N s) (grand pianos: about 1e-4 to 1e-2)");
    assert!((1e-4..1e-2).contains(&tt100));
}

#[test]
fn simply_supported_bare_plate_matches_the_closed_form() {
    let mut spec = grand();
    spec.plate.edges = Edges::SimplySupported;
    spec.ribs = None;
    spec.bridges.clear();
    spec.basis.terms_x = 12;
    spec.basis.terms_y = 12;
    spec.reduction.f_min_hz = 1.0;
    let solved = spec.solve().unwrap();
    let mut exact: Vec<f64> = (1..=12)
        .flat_map(|m| (1..=12).map(move |n| (m, n)))
        .map(|(m, n)| spec.plate.simply_supported_freq_hz(m, n))
        .collect();
    exact.sort_by(f64::total_cmp);
    println!("simply-supported bare plate, Ritz vs closed form (first 20 modes):");
    let mut worst: f64 = 0.0;
    for (k, (ritz, closed)) in solved.modes.freq_hz.iter().zip(&exact).take(20).enumerate() {
        let err = 100.0 * (ritz / closed - 1.0);
        worst = worst.max(err.abs());
        println!(
            "  {:2}: {ritz:9.3} Hz vs {closed:9.3} Hz ({err:+.2e} %)",
            k + 1
        );
    }
    println!("  worst {worst:.2e} % (limit 0.5 %)");
    assert!(worst < 0.5);
}

#[test]
fn asset_loads_with_every_key() {
    let board = SoundboardModes::load_file(Path::new(&format!(
        "{}/{ASSET}",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let names: Vec<&str> = board.points.iter().map(|p| p.name.as_str()).collect();
    println!(
        "{} modes, {} bridge points: {} … {}",
        board.len(),
        names.len(),
        names[0],
        names[names.len() - 1]
    );
    assert_eq!(names.len(), 88);
    assert_eq!((names[0], names[15], names[87]), ("A0", "C2", "C8"));
}
