//! The board in its own complex modes, known in closed form, formed once per stage for all voices.

use super::kernels::*;
use crate::engine::modal::*;
use faer::c64;

/// The board in its own complex modes, known in closed form: each mode `qdd = -w² q - 2 zeta w
/// qdot + f` is `q = 2 Re z`, `qdot = 2 Re(lambda z)`, `z' = lambda z + f / (2 i Im lambda)`. The
/// board is read at each voice's point through its modal displacements and velocities (real,
/// formed once per stage for all voices) and driven by one modal force per stage, the sum over
/// voices of `Phi_b^T F` (Eq. 17) — so each voice costs a few dot products over the board's modes.
#[derive(Debug, Clone)]
pub(super) struct Board {
    pub(super) zr: Vec<f64>,
    pub(super) zi: Vec<f64>,
    /// `lambda` and `e^{lambda h}`, `e^{lambda h/2}` (re, im).
    pub(super) lam: [Vec<f64>; 2],
    pub(super) ef: [Vec<f64>; 2],
    pub(super) eh: [Vec<f64>; 2],
    /// What one unit of modal force at an earlier stage adds to `q` and `qdot` at a later one:
    /// `2 Re(k gamma)` and `2 Re(lambda k gamma)` for `k = Q` (kind 0) and `(E - 1) Q` (kind 1).
    pub(super) cq: [Vec<f64>; 2],
    pub(super) cv: [Vec<f64>; 2],
    /// `f1 gamma`, `f2 gamma`, `f3 gamma` (re, im): the final update per unit modal force.
    pub(super) g: [[Vec<f64>; 2]; 3],
    pub(super) omega2: Vec<f64>,
    /// `2 zeta omega` (1/s).
    pub(super) damp: Vec<f64>,
    pub(super) volume: Vec<f64>,
    /// Scratch: modal `q`, `qdot` through `1`, `E`, `E²` at the step's start; at the stage, and
    /// the modal acceleration there; the modal force of each stage.
    pub(super) start: [[Vec<f64>; 2]; 3],
    pub(super) stage: [Vec<f64>; 2],
    pub(super) acc: Vec<f64>,
    /// This half's modal force of each stage, and both halves' together.
    pub(super) force: [Vec<f64>; 4],
    pub(super) total: [Vec<f64>; 4],
}

impl Board {
    pub(super) fn new(
        board: &crate::engine::physics::soundboard::SoundboardModes,
        h: f64,
    ) -> Board {
        let n = board.len();
        let mut b = Board {
            zr: vec![0.0; n],
            zi: vec![0.0; n],
            lam: [vec![0.0; n], vec![0.0; n]],
            ef: [vec![0.0; n], vec![0.0; n]],
            eh: [vec![0.0; n], vec![0.0; n]],
            cq: [vec![0.0; n], vec![0.0; n]],
            cv: [vec![0.0; n], vec![0.0; n]],
            g: std::array::from_fn(|_| [vec![0.0; n], vec![0.0; n]]),
            omega2: vec![0.0; n],
            damp: vec![0.0; n],
            volume: board.volume_m2_per_sqrt_kg.clone(),
            start: std::array::from_fn(|_| [vec![0.0; n], vec![0.0; n]]),
            stage: [vec![0.0; n], vec![0.0; n]],
            acc: vec![0.0; n],
            force: std::array::from_fn(|_| vec![0.0; n]),
            total: std::array::from_fn(|_| vec![0.0; n]),
        };
        for i in 0..n {
            let mode = board.oscillator(i);
            let (w, zeta) = (mode.omega_rad_s, mode.damping_ratio);
            let lam = c64::new(-zeta * w, w * (1.0 - zeta * zeta).max(0.0).sqrt());
            let gamma = c64::new(1.0, 0.0) / c64::new(0.0, 2.0 * lam.im.max(f64::MIN_POSITIVE));
            let [q, eq, f1, f2, f3] = etd_weights(lam, h);
            let e = |t: f64| {
                let m = (lam.re * t).exp();
                c64::new(m * (lam.im * t).cos(), m * (lam.im * t).sin())
            };
            let set = |a: &mut [Vec<f64>; 2], x: c64| {
                a[0][i] = x.re;
                a[1][i] = x.im;
            };
            set(&mut b.lam, lam);
            set(&mut b.ef, e(h));
            set(&mut b.eh, e(0.5 * h));
            for (kind, k) in [q, eq].into_iter().enumerate() {
                b.cq[kind][i] = 2.0 * (k * gamma).re;
                b.cv[kind][i] = 2.0 * (lam * k * gamma).re;
            }
            for (g, f) in b.g.iter_mut().zip([f1, f2, f3]) {
                set(g, f * gamma);
            }
            b.omega2[i] = w * w;
            b.damp[i] = 2.0 * zeta * w;
        }
        b
    }

    /// The modal acceleration at the stage, once its total modal force is known (Eq. 4, 17).
    #[inline(always)]
    pub(super) fn accel(&mut self, stage: usize) {
        let n = self.zr.len();
        let (q, v, f) = (
            &self.stage[0][..n],
            &self.stage[1][..n],
            &self.total[stage][..n],
        );
        let (w2, c, acc) = (&self.omega2[..n], &self.damp[..n], &mut self.acc[..n]);
        for i in 0..n {
            acc[i] = f[i] - w2[i] * q[i] - c[i] * v[i];
        }
    }

    /// Modal `q` and `qdot` of the state `e z`.
    pub(super) fn modal(&self, e: Option<&[Vec<f64>; 2]>, i: usize) -> (f64, f64) {
        let (mut a, mut b) = (self.zr[i], self.zi[i]);
        if let Some(e) = e {
            (a, b) = (e[0][i] * a - e[1][i] * b, e[0][i] * b + e[1][i] * a);
        }
        (2.0 * a, 2.0 * (self.lam[0][i] * a - self.lam[1][i] * b))
    }

    /// Fill `start` with the modal displacements and velocities through `1`, `E`, `E²`.
    #[inline(always)]
    pub(super) fn read_start(&mut self) {
        let n = self.zr.len();
        let (zr, zi) = (&self.zr[..n], &self.zi[..n]);
        let (lr, li) = (&self.lam[0][..n], &self.lam[1][..n]);
        for (which, e) in [None, Some(&self.eh), Some(&self.ef)]
            .into_iter()
            .enumerate()
        {
            let [q, v] = &mut self.start[which];
            let (q, v) = (&mut q[..n], &mut v[..n]);
            match e {
                None => {
                    for i in 0..n {
                        q[i] = 2.0 * zr[i];
                        v[i] = 2.0 * (lr[i] * zr[i] - li[i] * zi[i]);
                    }
                }
                Some([er, ei]) => {
                    let (er, ei) = (&er[..n], &ei[..n]);
                    for i in 0..n {
                        let a = er[i] * zr[i] - ei[i] * zi[i];
                        let b = er[i] * zi[i] + ei[i] * zr[i];
                        q[i] = 2.0 * a;
                        v[i] = 2.0 * (lr[i] * a - li[i] * b);
                    }
                }
            }
        }
    }

    /// Form the stage's modal `q`, `qdot`: row `which` of the start plus the responses to the
    /// modal forces of the earlier stages in `terms`.
    #[inline(always)]
    pub(super) fn form_stage<const FMA: bool>(
        &mut self,
        which: usize,
        terms: &[(usize, usize, f64); 2],
    ) {
        let n = self.zr.len();
        for x in 0..2 {
            let (c, dst) = (if x == 0 { &self.cq } else { &self.cv }, &mut self.stage[x]);
            dst.copy_from_slice(&self.start[which][x]);
            for &(p, kind, coef) in terms {
                if coef != 0.0 {
                    let (c, f) = (&c[kind][..n], &self.total[p][..n]);
                    for i in 0..n {
                        dst[i] = fma::<FMA>(coef * c[i], f[i], dst[i]);
                    }
                }
            }
        }
    }

    /// The stage's total modal force: this replica's own plus `other` (the other half's). One
    /// function for both ways of running the halves, so that they add alike bit for bit.
    #[inline(always)]
    pub(super) fn sum_forces(&mut self, stage: usize, other: impl Iterator<Item = f64>) {
        for ((t, f), o) in self.total[stage]
            .iter_mut()
            .zip(&self.force[stage])
            .zip(other)
        {
            *t = f + o;
        }
    }

    /// The step's end: `z <- E² z + f1 gamma F0 + f2 gamma (F1 + F2) + f3 gamma F3`, and the
    /// modal forces cleared for the next step.
    #[inline(always)]
    pub(super) fn advance<const FMA: bool>(&mut self) {
        let n = self.zr.len();
        let (zr, zi) = (&mut self.zr[..n], &mut self.zi[..n]);
        let (er, ei) = (&self.ef[0][..n], &self.ef[1][..n]);
        let [[g1r, g1i], [g2r, g2i], [g3r, g3i]] = &self.g;
        let [f0, f1, f2, f3] = &self.total;
        let (f0, f1, f2, f3) = (&f0[..n], &f1[..n], &f2[..n], &f3[..n]);
        for i in 0..n {
            let (a, b) = (zr[i], zi[i]);
            let mid = f1[i] + f2[i];
            let re = fma::<FMA>(er[i], a, -ei[i] * b);
            let im = fma::<FMA>(er[i], b, ei[i] * a);
            let re = fma::<FMA>(
                g1r[i],
                f0[i],
                fma::<FMA>(g2r[i], mid, fma::<FMA>(g3r[i], f3[i], re)),
            );
            let im = fma::<FMA>(
                g1i[i],
                f0[i],
                fma::<FMA>(g2i[i], mid, fma::<FMA>(g3i[i], f3[i], im)),
            );
            zr[i] = re;
            zi[i] = im;
        }
        self.force.iter_mut().for_each(|f| f.fill(0.0));
    }

    /// Net volume velocity (m^3/s).
    pub(super) fn volume_velocity(&self) -> f64 {
        (0..self.zr.len())
            .map(|i| self.volume[i] * self.modal(None, i).1)
            .sum()
    }

    /// `(phi . q, phi . qdot)` at the current state.
    pub(super) fn at(&self, phi: &[f64]) -> (f64, f64) {
        (0..self.zr.len())
            .map(|i| {
                let (q, v) = self.modal(None, i);
                (phi[i] * q, phi[i] * v)
            })
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// Mechanical energy (J).
    pub(super) fn energy_j(&self) -> f64 {
        (0..self.zr.len())
            .map(|i| {
                let (q, v) = self.modal(None, i);
                0.5 * (v * v + self.omega2[i] * q * q)
            })
            .sum()
    }

    pub(super) fn clear(&mut self) {
        self.zr.fill(0.0);
        self.zi.fill(0.0);
    }
}
