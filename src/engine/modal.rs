//! A second-order block `qdd = -K q - C qdot + b u` (symmetric `K` and `C`) in its complex modes
//! (conjugate pairs stored once), with its output rows, input vectors and modal energies; the
//! weights of an exact step with a linear input and of ETDRK4 (the hammer's stages,
//! [`crate::engine::exact`]).
//!
//! A mode `lambda` with shape `q` (`(lambda^2 + lambda C + K) q = 0`) is the state
//! `x = [q; lambda q]`. As `K` and `C` are symmetric its left vector is `y = [(lambda + C) q; q]`,
//! so with `q` scaled to `q^T (2 lambda + C) q = 1` (`y^T x = 1`) the force `b` drives the mode by
//! `q^T b`: no inverse of the eigenvector matrix is needed.

use crate::engine::kernels::LANES;
use crate::engine::spec::BuildError;
use faer::{c64, Mat};

/// A block `qdd = -K q - C qdot + b u` in its complex modes.
///
/// Of each complex-conjugate pair of modes only one is stored (its partner is its conjugate: the
/// block is real), with weight 2 folded into the output rows; real (overdamped) modes have weight 1.
pub(crate) struct Modal {
    pub(crate) n: usize,
    /// Each kept mode's eigenvalue `lambda` (1/s), in order of `|lambda|`.
    pub(crate) lambda: Vec<c64>,
    /// Each kept mode's weight: 2 for one of a conjugate pair, 1 for a real mode.
    pub(crate) weight: Vec<f64>,
    /// Each kept mode's shape `q` (a column, `n` rows), scaled to `q^T (2 lambda + C) q = 1`.
    pub(crate) shape: Mat<c64>,
    /// Kept modes rounded up to whole SIMD lanes.
    pub(crate) padded: usize,
}

impl Modal {
    /// Diagonalise `qdd = -K q - C qdot + ...` (dense `n × n`, row-major) as one dense
    /// eigenproblem of order `2n`.
    pub(crate) fn dense(k: &[f64], c: &[f64], n: usize) -> Result<Modal, BuildError> {
        // Balanced: velocities in units of `omega_s` (the highest undamped frequency), so that
        // both blocks of the matrix are of one size (`x = (q, qdot / omega_s)`). Unbalanced, the
        // entries span 1 to omega^2 ~ 1e10, and the QR iteration can fail to converge (it did
        // not on key 63, B5, with the board's high modes alone).
        let omega_s = (0..n).map(|i| k[i * n + i]).fold(1.0, f64::max).sqrt();
        let a = Mat::<f64>::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
            (true, true) => 0.0,
            (true, false) => f64::from(u8::from(j - n == i)) * omega_s,
            (false, true) => -k[(i - n) * n + j] / omega_s,
            (false, false) => -c[(i - n) * n + (j - n)],
        });
        let eig = a.eigen().map_err(|_| BuildError::Modes)?;
        let s = eig.S().column_vector().to_owned();
        // Representatives: Im > 0 of each pair (weight 2), real eigenvalues (weight 1).
        let scale = (0..2 * n).map(|i| s[i].norm()).fold(0.0, f64::max).max(1.0);
        let keep: Vec<(usize, f64)> = (0..2 * n)
            .filter_map(|i| {
                let im = s[i].im;
                if im > 1e-12 * scale {
                    Some((i, 2.0))
                } else if im.abs() <= 1e-12 * scale {
                    Some((i, 1.0))
                } else {
                    None
                }
            })
            .collect();
        let pairs = keep.iter().filter(|(_, w)| *w == 2.0).count();
        if 2 * pairs + (keep.len() - pairs) != 2 * n || !s.iter().all(|x| x.re.is_finite()) {
            return Err(BuildError::Modes);
        }
        // The shape is the displacement half of each eigenvector (the balanced state holds
        // `q` at full size for every mode up to `omega_s`).
        let shape = Mat::<c64>::from_fn(n, keep.len(), |i, j| eig.U()[(i, keep[j].0)]);
        let lambda: Vec<c64> = keep.iter().map(|&(i, _)| s[i]).collect();
        let weight = keep.iter().map(|&(_, w)| w).collect();
        Modal::scaled(lambda, weight, shape, c)
    }

    /// The modes `lambda` with shapes `shape` (of any scale) of the block with damping `c`
    /// (dense `n × n`, row-major), each shape scaled to `q^T (2 lambda + C) q = 1` and the modes
    /// put in order of `|lambda|` (the natural frequency of a pair, the decay rate of a real
    /// mode): a voice keeps its modes as a prefix of this order and lets the rest follow the
    /// bridge quasi-statically ([`crate::engine::exact`]), which holds for the modes far above
    /// what drives them.
    pub(crate) fn scaled(
        lambda: Vec<c64>,
        weight: Vec<f64>,
        shape: Mat<c64>,
        c: &[f64],
    ) -> Result<Modal, BuildError> {
        let n = shape.nrows();
        let damping = Mat::<f64>::from_fn(n, n, |i, j| c[i * n + j]);
        let (re, im) = real_parts(&shape);
        let (cre, cim) = (&damping * &re, &damping * &im);
        let mut order: Vec<usize> = (0..lambda.len()).collect();
        order.sort_by(|&a, &b| lambda[a].norm().total_cmp(&lambda[b].norm()));
        // Modes of one eigenvalue (alike strings, or a direction's pair the bridge treats
        // alike) are made orthogonal in `x^T (2 lambda + C) y`, which distinct modes are by
        // symmetry: within each, a Gram-Schmidt sweep in that form.
        let column = |m: usize| -> (Vec<c64>, Vec<c64>) {
            (
                (0..n).map(|i| shape[(i, m)]).collect(),
                (0..n).map(|i| c64::new(cre[(i, m)], cim[(i, m)])).collect(),
            )
        };
        let form = |l: c64, x: &[c64], y: &[c64], cy: &[c64]| -> c64 {
            (0..n).map(|i| x[i] * (y[i] * l * 2.0 + cy[i])).sum()
        };
        let mut scaled = Mat::<c64>::zeros(n, order.len());
        let mut group: Vec<(Vec<c64>, Vec<c64>)> = vec![];
        for (to, &m) in order.iter().enumerate() {
            let l = lambda[m];
            let first = to - group.len();
            if group.is_empty() || (lambda[order[first]] - l).norm() > 1e-8 * l.norm() {
                group.clear();
            }
            let (mut x, mut cx) = column(m);
            for (y, cy) in &group {
                let by = form(l, y, &x, &cx);
                for i in 0..n {
                    x[i] -= y[i] * by;
                    cx[i] -= cy[i] * by;
                }
            }
            let by = form(l, &x, &x, &cx).sqrt().inv();
            if !(by.re.is_finite() && by.im.is_finite()) {
                return Err(BuildError::Modes);
            }
            x.iter_mut().for_each(|v| *v *= by);
            cx.iter_mut().for_each(|v| *v *= by);
            for i in 0..n {
                scaled[(i, to)] = x[i];
            }
            group.push((x, cx));
        }
        let kept = order.len();
        Ok(Modal {
            n,
            lambda: order.iter().map(|&m| lambda[m]).collect(),
            weight: order.iter().map(|&m| weight[m]).collect(),
            shape: scaled,
            padded: kept.div_ceil(LANES) * LANES,
        })
    }

    /// The output row `r = c^T V` (weighted) reading `c^T q`, or `c^T qdot` if `velocity`.
    pub(crate) fn row(&self, c: &[f64], velocity: bool) -> Vec<c64> {
        self.input(c)
            .into_iter()
            .enumerate()
            .map(|(m, cq)| {
                let v = if velocity {
                    self.lambda[m]
                } else {
                    c64::new(1.0, 0.0)
                };
                cq * v * self.weight[m]
            })
            .collect()
    }

    /// The input vector `g = V^-1 [0; b]` of a force distribution `b` on the accelerations:
    /// `q^T b` for each mode.
    pub(crate) fn input(&self, b: &[f64]) -> Vec<c64> {
        (0..self.lambda.len())
            .map(|m| {
                let mut acc = c64::new(0.0, 0.0);
                for (i, &bi) in b.iter().enumerate() {
                    acc += self.shape[(i, m)] * bi;
                }
                acc
            })
            .collect()
    }

    /// Per stored mode, the mechanical energy per `|z|²` (J): the cycle-averaged
    /// `1/2 (qdot^T qdot + q^T K q)` of `w Re(v z)` for the mode's eigenvector `v`.
    pub(crate) fn energy(&self, k: &[f64]) -> Vec<f64> {
        let n = self.n;
        // `K` is symmetric, so `v^H K v = a^T K a + b^T K b` for `v = a + i b`: two real products
        // over every kept mode at once.
        let (a, b) = real_parts(&self.shape);
        let stiffness = Mat::<f64>::from_fn(n, n, |i, j| k[i * n + j]);
        let (ka, kb) = (&stiffness * &a, &stiffness * &b);
        let mut e: Vec<f64> = (0..self.lambda.len())
            .map(|m| {
                let w = self.weight[m];
                let speed = self.lambda[m].norm_sqr();
                let kinetic: f64 =
                    (0..n).map(|i| self.shape[(i, m)].norm_sqr()).sum::<f64>() * speed;
                let potential: f64 = (0..n)
                    .map(|i| a[(i, m)] * ka[(i, m)] + b[(i, m)] * kb[(i, m)])
                    .sum();
                0.25 * w * w * (kinetic + potential)
            })
            .collect();
        e.resize(self.padded, 0.0);
        e
    }
}

/// The real and imaginary parts of a complex matrix.
pub(crate) fn real_parts(m: &Mat<c64>) -> (Mat<f64>, Mat<f64>) {
    (
        Mat::<f64>::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)].re),
        Mat::<f64>::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)].im),
    )
}

#[cfg(test)]
impl Modal {
    /// `c^T (K - omega^2 + i omega C)^-1 b` from the modes: each pair's two poles.
    pub(crate) fn response(&self, c: &[f64], b: &[f64], omega: f64) -> c64 {
        let (row, input) = (self.row(c, false), self.input(b));
        let s = c64::new(0.0, omega);
        (0..row.len())
            .map(|m| {
                let (l, w) = (self.lambda[m], self.weight[m]);
                let r = row[m] / w * input[m];
                if w == 2.0 {
                    r / (s - l) + r.conj() / (s - l.conj())
                } else {
                    r / (s - l)
                }
            })
            .sum()
    }
}

/// The same by a direct solve of the dense system (`k`, `damping` row-major `n × n`).
#[cfg(test)]
pub(crate) fn solved_response(k: &[f64], damping: &[f64], c: &[f64], b: &[f64], omega: f64) -> c64 {
    use faer::linalg::solvers::Solve;
    let n = c.len();
    let p = Mat::<c64>::from_fn(n, n, |i, j| {
        let mass = if i == j { omega * omega } else { 0.0 };
        c64::new(k[i * n + j] - mass, omega * damping[i * n + j])
    });
    let rhs = Mat::<c64>::from_fn(n, 1, |i, _| c64::new(b[i], 0.0));
    let x = p.partial_piv_lu().solve(&rhs);
    (0..n).map(|i| x[(i, 0)] * c[i]).sum()
}

/// ETDRK4 coefficients of one mode `lambda` for step `h`: `Q = (e^{lambda h/2} - 1)/lambda`,
/// `(e^{lambda h/2} - 1) Q`, and the final weights `f1`, `f2` (of `N(a) + N(b)`), `f3`:
/// `h {-4 - z + e^z (4 - 3z + z^2)} / z^3`, `2h {2 + z + e^z (z - 2)} / z^3`,
/// `h {-4 - 3z - z^2 + e^z (4 - z)} / z^3` with `z = lambda h`. Near `z = 0` these cancel, so
/// there they are the mean over a circle of radius 1 around `z` (Kassam & Trefethen 2005).
pub(crate) fn etd_weights(lambda: c64, h: f64) -> [c64; 5] {
    let one = c64::new(1.0, 0.0);
    let exp = |z: c64| {
        let m = z.re.exp();
        c64::new(m * z.im.cos(), m * z.im.sin())
    };
    let direct = |z: c64| -> [c64; 4] {
        let (e, e2) = (exp(z), exp(z * 0.5));
        let z3 = z * z * z;
        [
            (e2 - one) / z,
            ((-one * 4.0) - z + e * (one * 4.0 - z * 3.0 + z * z)) / z3,
            ((one * 2.0) + z + e * (z - one * 2.0)) / z3 * 2.0,
            ((-one * 4.0) - z * 3.0 - z * z + e * (one * 4.0 - z)) / z3,
        ]
    };
    let z = lambda * h;
    let phi = cancellation_free(z, direct);
    // phi[0] is Q / h; the others are already per unit h.
    let q = phi[0] * h;
    let e2 = exp(z * 0.5);
    [q, (e2 - one) * q, phi[1] * h, phi[2] * h, phi[3] * h]
}

/// `direct(z)` where its terms do not cancel (`|z| > 0.5`), else its mean over the circle of
/// radius 1 around `z` (Kassam & Trefethen 2005: the functions are analytic, so the mean is
/// their value, without the cancellation).
fn cancellation_free<const K: usize>(z: c64, direct: impl Fn(c64) -> [c64; K]) -> [c64; K] {
    if z.norm() > 0.5 {
        return direct(z);
    }
    const POINTS: usize = 64;
    let mut acc = [c64::new(0.0, 0.0); K];
    for k in 0..POINTS {
        let t = 2.0 * std::f64::consts::PI * (k as f64 + 0.5) / POINTS as f64;
        let v = direct(z + c64::new(t.cos(), t.sin()));
        for (a, v) in acc.iter_mut().zip(v) {
            *a += v;
        }
    }
    acc.map(|a| a / POINTS as f64)
}

/// Weights of an input that is linear over the step, `u(t_n + tau) = u0 + s tau`, on a mode
/// `lambda`: `z' = e^{lambda h} z + (h phi1) (g u0) + (h^2 phi2) (g s)` with
/// `phi1(x) = (e^x - 1)/x`, `phi2(x) = (e^x - 1 - x)/x^2`, `x = lambda h` — exact for such an input.
/// Near `x = 0` they are the mean over a circle of radius 1 around `x`, as in [`etd_weights`].
pub(crate) fn input_weights(lambda: c64, h: f64) -> [c64; 2] {
    let one = c64::new(1.0, 0.0);
    let direct = |x: c64| -> [c64; 2] {
        let m = x.re.exp();
        let e = c64::new(m * x.im.cos(), m * x.im.sin());
        [(e - one) / x, (e - one - x) / (x * x)]
    };
    let phi = cancellation_free(lambda * h, direct);
    [phi[0] * h, phi[1] * h * h]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit velocity kick of `qdd + c qdot + k q = 0` read through the complex modes, against the
    /// closed form (weights 2 for a conjugate pair, 1 for a real mode).
    fn kick_response(k: f64, c: f64, exact: impl Fn(f64) -> f64) -> f64 {
        let h = 1e-4;
        let modal = Modal::dense(&[k], &[c], 1).unwrap();
        let (row, g) = (modal.row(&[1.0], false), modal.input(&[1.0]));
        let mut worst: f64 = 0.0;
        let mut peak: f64 = 0.0;
        for step in 0..2000 {
            let t = step as f64 * h;
            let y: f64 = (0..row.len())
                .map(|m| (row[m] * (modal.lambda[m] * t).exp() * g[m]).re)
                .sum();
            worst = worst.max((y - exact(t)).abs());
            peak = peak.max(exact(t).abs());
        }
        worst / peak
    }

    #[test]
    fn each_modes_energy_is_that_of_its_motion() {
        // Three coupled, damped oscillators (symmetric K and C): each kept mode's energy per
        // |z|^2 against `1/4 w^2 (|v_qdot|^2 + v_q^H K v_q)` summed term by term.
        let n = 3;
        let k = [
            4.0e6, -1.0e6, 0.0, -1.0e6, 5.0e6, -2.0e6, 0.0, -2.0e6, 9.0e6,
        ];
        let c = [20.0, 1.0, 0.0, 1.0, 15.0, 2.0, 0.0, 2.0, 30.0];
        let modal = Modal::dense(&k, &c, n).unwrap();
        let fast = modal.energy(&k);
        for (slot, &w) in modal.weight.iter().enumerate() {
            // The state `[q; lambda q]`.
            let v = |i: usize| {
                let q = modal.shape[(i % n, slot)];
                if i < n {
                    q
                } else {
                    q * modal.lambda[slot]
                }
            };
            let kinetic: f64 = (0..n).map(|i| v(n + i).norm_sqr()).sum();
            let potential: f64 = (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| (v(i).conj() * v(j) * k[i * n + j]).re)
                        .sum::<f64>()
                })
                .sum();
            let direct = 0.25 * w * w * (kinetic + potential);
            println!(
                "mode {slot}: {:.6e} J, term by term {direct:.6e} J",
                fast[slot]
            );
            assert!(
                (fast[slot] - direct).abs() <= 1e-12 * direct.abs(),
                "{slot}"
            );
        }
    }

    #[test]
    fn complex_modes_give_the_oscillators_kick_response() {
        let (w, zeta): (f64, f64) = (2.0 * std::f64::consts::PI * 200.0, 0.05);
        let wd = w * (1.0 - zeta * zeta).sqrt();
        let under = kick_response(w * w, 2.0 * zeta * w, |t| {
            (-zeta * w * t).exp() * (wd * t).sin() / wd
        });
        // Overdamped: two real modes.
        let (l1, l2) = (-300.0_f64, -2000.0_f64);
        let over = kick_response(l1 * l2, -(l1 + l2), |t| {
            ((l1 * t).exp() - (l2 * t).exp()) / (l1 - l2)
        });
        println!("kick response vs closed form: underdamped {under:.1e}, overdamped {over:.1e}");
        assert!(under < 1e-9 && over < 1e-9);
    }

    #[test]
    fn input_weights_integrate_a_ramp_exactly() {
        // y' = lambda y + u0 + s t from y(0) = 0, closed form at t = h, against the weights.
        let (h, u0, s) = (1e-3, 0.7, -40.0);
        let mut worst: f64 = 0.0;
        for x in [
            c64::new(-0.3, 0.2),
            c64::new(-0.01, 2.5),
            c64::new(-4.0, 1.0),
            c64::new(-0.1, 0.05),
        ] {
            let l = x / h;
            let e = (l * h).exp();
            let one = c64::new(1.0, 0.0);
            // Particular solution of a ramp: y_p = -(u0 + s t)/l - s/l^2.
            let yp = |t: f64| -(one * (u0 + s * t)) / l - one * s / (l * l);
            let exact = yp(h) - e * yp(0.0);
            let [w1, w2] = input_weights(l, h);
            let got = w1 * u0 + w2 * s;
            worst = worst.max(((got - exact) / exact).norm());
        }
        println!("linear-input weights vs the closed form: {worst:.1e}");
        assert!(worst < 1e-9, "{worst:e}");
    }

    #[test]
    fn etd_weights_sum_to_phi1_and_tend_to_rk4() {
        let h = 1e-3;
        // For a constant nonlinear term the step is exact: f1 + 2 f2 + f3 = (e^z - 1) / lambda.
        let mut worst: f64 = 0.0;
        for z in [
            c64::new(-0.3, 0.2),
            c64::new(-0.49, 0.0),
            c64::new(-0.51, 0.0),
            c64::new(-0.01, 2.5),
            c64::new(-4.0, 1.0),
        ] {
            let lambda = z / h;
            let [_, _, f1, f2, f3] = etd_weights(lambda, h);
            let m = z.re.exp();
            let phi1 = (c64::new(m * z.im.cos() - 1.0, m * z.im.sin())) / lambda;
            worst = worst.max(((f1 + f2 * 2.0 + f3 - phi1) / phi1).norm());
        }
        // As lambda h -> 0 the weights become classical RK4's h/6, h/3, h/6 (f2 weighs a + b).
        let [q, _, f1, f2, f3] = etd_weights(c64::new(-1e-6, 1e-6) / h, h);
        let rk4 = [(q, 0.5 * h), (f1, h / 6.0), (f2, h / 3.0), (f3, h / 6.0)]
            .map(|(x, y)| ((x.re - y) / y).abs())
            .into_iter()
            .fold(0.0, f64::max);
        println!("ETDRK4 weights: sum vs phi1 {worst:.1e}; small z vs RK4 {rk4:.1e}");
        assert!(worst < 1e-12, "f1 + 2 f2 + f3 != phi1: {worst:e}");
        assert!(rk4 < 1e-5, "weights at z -> 0 differ from RK4's: {rk4:e}");
    }
}
