//! A key's modes found through its bridge point.
//!
//! Held still, the bridge point splits a key into small systems: each string direction on its
//! contact spring (its modes, their losses, the duplex felt) and the key's board modes on every
//! string's spring. Each is diagonalised alone (modes `mu_j`, shapes `q_j` scaled to
//! `q^T (2 mu + C) q = 1`, so that a held system's `(s^2 + s C + K)^-1 = sum_j q_j q_j^T /
//! (s - mu_j)`). The key's modes are then the roots of a polynomial of degree `2n`,
//!
//! ```text
//! p(s) = det(I₃ - G(s) Z(s)) prod_j (s - mu_j)
//! G_ab(s) = sum_board j (phi_a . q_j)(phi_b . q_j) / (s - mu_j)     the held board at the point
//! Z_d(s) = (k_d + s c_d)^2 sum_strings(d) sum_j (psi . q_j)^2 / (s - mu_j)
//! ```
//! (`phi_d` the board modes' shapes at the point in direction `d`, `psi` a string's modes at its
//! end, `k_d`, `c_d` the contact spring and damper), found all at once by Aberth's iteration from
//! the held modes. A mode's shape follows from the bridge point's motion `u`, `(I - G Z) u = 0`:
//! the board's part is `sum_j q_j (phi . q_j) . (Z u) / (s - mu_j)`, and a string's in direction
//! `d` is `(k_d + s c_d) u_d sum_j q_j (psi . q_j) / (s - mu_j)`. This costs a few small
//! eigenproblems, Aberth's sweeps of `O(n^2)` each and a few matrix products for the shapes and
//! the checks: far less than the QR iterations of the key's dense problem of order `2n`.
//!
//! Every solve is checked: each mode's residual in `(s^2 + s C + K) q`, and the modes' completeness
//! (a force and a displacement rebuilt from their modal parts). Where a check fails, or the split
//! does not hold (a direction the board does not move in leaves its strings' held modes as they
//! are), [`BridgeSystem::modes`] gives none and the key is diagonalised densely
//! ([`Modal::dense`]).

use crate::engine::modal::{real_parts, Modal};
use faer::{c64, Mat};

/// One string's modes in one direction: a diagonal block of the key's `K` and a dense one of `C`.
pub(crate) struct Strand {
    /// The direction's index (T, L, P: [`crate::engine::spec::Direction::index`]).
    pub(crate) direction: usize,
    /// Where its modes start in the key's `q`.
    pub(crate) start: usize,
    /// Each mode's `omega^2` (1/s^2).
    pub(crate) omega2: Vec<f64>,
    /// The modes' damping (1/s, `m × m` row-major): their own losses and the duplex felt.
    pub(crate) damping: Vec<f64>,
    /// Each mode's shape at the string's end on its contact spring (1/sqrt(kg)).
    pub(crate) at_bridge: Vec<f64>,
}

/// A key's strings on contact springs to one point of its board modes (Eq. 6):
/// `K = blocks + sum k_d w w^T`, `C = blocks + sum c_d w w^T`, `w` a string's end relative to the
/// point.
pub(crate) struct BridgeSystem {
    pub(crate) n: usize,
    pub(crate) strands: Vec<Strand>,
    /// Where the board's modes start in `q` (after every strand).
    pub(crate) board_start: usize,
    /// Each board mode's `omega^2` (1/s^2) and damping (1/s).
    pub(crate) board_omega2: Vec<f64>,
    pub(crate) board_damping: Vec<f64>,
    /// The board modes' shapes at the point, per direction (1/sqrt(kg)).
    pub(crate) board_at_point: [Vec<f64>; 3],
    /// The contact springs (N/m) and dampers (N s/m), per direction.
    pub(crate) contact_stiffness_n_m: [f64; 3],
    pub(crate) contact_damping_n_s_m: [f64; 3],
}

impl BridgeSystem {
    /// Strand `s`'s end relative to the point, over `q`: `psi` on its modes, `-phi_d` on the
    /// board's.
    pub(crate) fn contact(&self, s: usize) -> Vec<f64> {
        let strand = &self.strands[s];
        let mut w = vec![0.0; self.n];
        for (i, &x) in strand.at_bridge.iter().enumerate() {
            w[strand.start + i] = x;
        }
        for (i, &x) in self.board_at_point[strand.direction].iter().enumerate() {
            w[self.board_start + i] = -x;
        }
        w
    }

    /// `K` and `C` (dense `n × n`, row-major).
    pub(crate) fn dense(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.n;
        let (mut k, mut c) = (vec![0.0; n * n], vec![0.0; n * n]);
        for s in &self.strands {
            let m = s.omega2.len();
            for i in 0..m {
                k[(s.start + i) * n + s.start + i] += s.omega2[i];
                for j in 0..m {
                    c[(s.start + i) * n + s.start + j] += s.damping[i * m + j];
                }
            }
        }
        for (i, (&w2, &d)) in self
            .board_omega2
            .iter()
            .zip(&self.board_damping)
            .enumerate()
        {
            let at = self.board_start + i;
            k[at * n + at] += w2;
            c[at * n + at] += d;
        }
        for s in 0..self.strands.len() {
            let d = self.strands[s].direction;
            let w = self.contact(s);
            let nz: Vec<(usize, f64)> = w
                .iter()
                .enumerate()
                .filter(|(_, x)| **x != 0.0)
                .map(|(i, x)| (i, *x))
                .collect();
            let (kc, cc) = (self.contact_stiffness_n_m[d], self.contact_damping_n_s_m[d]);
            for &(i, wi) in &nz {
                for &(j, wj) in &nz {
                    k[i * n + j] += kc * wi * wj;
                    c[i * n + j] += cc * wi * wj;
                }
            }
        }
        (k, c)
    }

    /// The key's modes through the bridge, checked against `K` and `C` ([`Self::dense`]), or
    /// none where the split does not hold or a check fails.
    pub(crate) fn modes(&self, k: &[f64], c: &[f64]) -> Option<Modal> {
        let held = Held::systems(self)?;
        let roots = held.roots()?;
        let modal = held.shapes(&roots, c)?;
        checked(modal, k, c)
    }
}

/// A held system's modes, both of each conjugate pair.
struct Poles {
    mu: Vec<c64>,
    /// Each mode's shape (a column).
    shape: Mat<c64>,
    /// Each mode's shape at the bridge: `psi . q` (a strand), `phi_d . q` per direction (the
    /// board).
    at: Vec<[c64; 3]>,
}

impl Poles {
    /// The modes of `qdd = -K q - C qdot` (dense `m × m`), read at the bridge through `at`.
    fn of(k: &[f64], c: &[f64], m: usize, at: &[&[f64]]) -> Option<Poles> {
        let modal = Modal::dense(k, c, m).ok()?;
        let mut mu = vec![];
        let mut columns = vec![];
        for (j, (&l, &w)) in modal.lambda.iter().zip(&modal.weight).enumerate() {
            if w == 2.0 {
                mu.extend([l, l.conj()]);
                columns.extend([(j, false), (j, true)]);
            } else {
                mu.push(c64::new(l.re, 0.0));
                columns.push((j, false));
            }
        }
        let shape = Mat::<c64>::from_fn(m, mu.len(), |i, p| {
            let (j, conj) = columns[p];
            let q = modal.shape[(i, j)];
            if conj {
                q.conj()
            } else {
                q
            }
        });
        let at = (0..mu.len())
            .map(|p| {
                std::array::from_fn(|d| {
                    at.get(d).map_or(c64::new(0.0, 0.0), |a| {
                        a.iter().enumerate().map(|(i, &x)| shape[(i, p)] * x).sum()
                    })
                })
            })
            .collect();
        Some(Poles { mu, shape, at })
    }
}

/// Strands that are one another's copies (a unison's strings alike in a direction: L, whose
/// frequencies do not follow the tension, or strings tuned alike), held once.
struct Group {
    direction: usize,
    /// The strands' indices.
    members: Vec<usize>,
    poles: Poles,
}

/// The held systems of a key.
struct Held<'a> {
    system: &'a BridgeSystem,
    groups: Vec<Group>,
    board: Poles,
}

/// The held systems' sums at one `s`: the board's `G` and its derivative, each direction's
/// strings' `sum (psi . q)^2 / (s - mu)` and its derivative, and `sum 1 / (s - mu)`.
struct Sums {
    g: [[c64; 3]; 3],
    dg: [[c64; 3]; 3],
    h: [c64; 3],
    dh: [c64; 3],
    poles: c64,
}

impl<'a> Held<'a> {
    /// Diagonalise each group of alike strands and the board held at a still point; none if a
    /// direction with strands has no board motion.
    fn systems(system: &'a BridgeSystem) -> Option<Held<'a>> {
        let mut count = [0usize; 3];
        let mut members: Vec<Vec<usize>> = vec![];
        for (i, s) in system.strands.iter().enumerate() {
            count[s.direction] += 1;
            if system.board_at_point[s.direction].iter().all(|&x| x == 0.0) {
                return None;
            }
            let alike = |t: &Strand| {
                t.direction == s.direction
                    && t.omega2 == s.omega2
                    && t.damping == s.damping
                    && t.at_bridge == s.at_bridge
            };
            match members.iter_mut().find(|g| alike(&system.strands[g[0]])) {
                Some(group) => group.push(i),
                None => members.push(vec![i]),
            }
        }
        // A held system: `K = diag(omega^2) + sum k a a^T`, `C = damping + sum c a a^T` over
        // the springs `(k, c)` at its shapes `a` at the bridge.
        let held = |omega2: &[f64], damping: &[f64], at: &[&[f64]], springs: &[[f64; 2]]| {
            let m = omega2.len();
            let (mut k, mut c) = (vec![0.0; m * m], damping.to_vec());
            for i in 0..m {
                k[i * m + i] = omega2[i];
                for (a, [kd, cd]) in at.iter().zip(springs) {
                    for j in 0..m {
                        k[i * m + j] += kd * a[i] * a[j];
                        c[i * m + j] += cd * a[i] * a[j];
                    }
                }
            }
            Poles::of(&k, &c, m, at)
        };
        let spring = |d: usize| {
            [
                system.contact_stiffness_n_m[d],
                system.contact_damping_n_s_m[d],
            ]
        };
        let mut groups = vec![];
        for members in members {
            let s = &system.strands[members[0]];
            groups.push(Group {
                direction: s.direction,
                members,
                poles: held(
                    &s.omega2,
                    &s.damping,
                    &[&s.at_bridge],
                    &[spring(s.direction)],
                )?,
            });
        }
        // The board on every string's spring.
        let nb = system.board_omega2.len();
        let mut board_c = vec![0.0; nb * nb];
        for i in 0..nb {
            board_c[i * nb + i] = system.board_damping[i];
        }
        let at: Vec<&[f64]> = system.board_at_point.iter().map(|v| v.as_slice()).collect();
        let springs: Vec<[f64; 2]> = (0..3)
            .map(|d| spring(d).map(|x| x * count[d] as f64))
            .collect();
        let board = held(&system.board_omega2, &board_c, &at, &springs)?;
        Some(Held {
            system,
            groups,
            board,
        })
    }

    /// The sums at `s`.
    fn sums(&self, s: c64) -> Sums {
        let zero = c64::new(0.0, 0.0);
        let mut out = Sums {
            g: [[zero; 3]; 3],
            dg: [[zero; 3]; 3],
            h: [zero; 3],
            dh: [zero; 3],
            poles: zero,
        };
        for group in &self.groups {
            let (d, alike) = (group.direction, group.members.len() as f64);
            for (&mu, at) in group.poles.mu.iter().zip(&group.poles.at) {
                let r = (s - mu).inv();
                let a = at[0] * at[0] * r * alike;
                out.poles += r;
                out.h[d] += a;
                out.dh[d] -= a * r;
            }
        }
        for (&mu, at) in self.board.mu.iter().zip(&self.board.at) {
            let r = (s - mu).inv();
            out.poles += r;
            for a in 0..3 {
                for b in a..3 {
                    let x = at[a] * at[b] * r;
                    out.g[a][b] += x;
                    out.dg[a][b] -= x * r;
                }
            }
        }
        for a in 0..3 {
            for b in 0..a {
                out.g[a][b] = out.g[b][a];
                out.dg[a][b] = out.dg[b][a];
            }
        }
        out
    }

    /// `Z_d` and its derivative at `s` from the sums.
    fn impedance(&self, s: c64, sums: &Sums) -> ([c64; 3], [c64; 3]) {
        let sys = self.system;
        let z = std::array::from_fn(|d| {
            let delta =
                c64::new(sys.contact_stiffness_n_m[d], 0.0) + s * sys.contact_damping_n_s_m[d];
            delta * delta * sums.h[d]
        });
        let dz = std::array::from_fn(|d| {
            let c = sys.contact_damping_n_s_m[d];
            let delta = c64::new(sys.contact_stiffness_n_m[d], 0.0) + s * c;
            delta * c * 2.0 * sums.h[d] + delta * delta * sums.dh[d]
        });
        (z, dz)
    }

    /// `p'(s) / p(s)`.
    fn log_derivative(&self, s: c64) -> c64 {
        let sums = self.sums(s);
        let (z, dz) = self.impedance(s, &sums);
        let m = point_matrix(&sums.g, &z);
        let dm: [[c64; 3]; 3] = std::array::from_fn(|a| {
            std::array::from_fn(|b| -(sums.dg[a][b] * z[b] + sums.g[a][b] * dz[b]))
        });
        sums.poles + trace_of_solve(m, dm)
    }

    /// Every root of `p` by Aberth's iteration from the held modes: one of each conjugate pair
    /// (`Im > 0`) and the real ones; none if any fails to settle.
    fn roots(&self) -> Option<Vec<c64>> {
        const SETTLED: f64 = 1e-14;
        const SWEEPS: usize = 200;
        let mut z: Vec<c64> = vec![];
        let mut real: Vec<bool> = vec![];
        for (k, &mu) in self
            .groups
            .iter()
            .flat_map(|g| &g.poles.mu)
            .chain(&self.board.mu)
            .enumerate()
        {
            // A start beside each pole (where `p`'s two factors are each infinite or zero), at
            // its own angle so that equal poles start apart.
            let off = 1e-7 * mu.norm().max(1.0);
            if mu.im > 0.0 {
                let angle = k as f64 * 2.399_963_229_728_653;
                let start = mu + c64::new(angle.cos(), angle.sin()) * off;
                z.push(if start.im > 0.0 { start } else { start.conj() });
                real.push(false);
            } else if mu.im == 0.0 {
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                z.push(c64::new(mu.re + sign * off, 0.0));
                real.push(true);
            }
        }
        let mut settled = vec![false; z.len()];
        for _ in 0..SWEEPS {
            let mut moving = false;
            for i in 0..z.len() {
                if settled[i] {
                    continue;
                }
                let newton = self.log_derivative(z[i]).inv();
                let mut others = c64::new(0.0, 0.0);
                for (k, (&zk, &rk)) in z.iter().zip(&real).enumerate() {
                    if k != i {
                        others += (z[i] - zk).inv();
                    }
                    if !rk {
                        others += (z[i] - zk.conj()).inv();
                    }
                }
                let step = newton / (c64::new(1.0, 0.0) - newton * others);
                if !(step.re.is_finite() && step.im.is_finite()) {
                    return None;
                }
                let mut next = z[i] - step;
                if real[i] {
                    next.im = 0.0;
                } else if next.im < 0.0 {
                    next = next.conj();
                }
                z[i] = next;
                if step.norm() <= SETTLED * next.norm() {
                    settled[i] = true;
                } else {
                    moving = true;
                }
            }
            if !moving {
                return Some(z);
            }
        }
        None
    }

    /// Each root's shape from the bridge point's motion, and the modes of alike strands that
    /// leave the point still, scaled ([`Modal::scaled`] with the key's `C`); none where the
    /// point's motion is not one direction of `(I - G Z)`'s null space.
    fn shapes(&self, roots: &[c64], c: &[f64]) -> Option<Modal> {
        let sys = self.system;
        // The modes in which alike strands move against one another: each held mode (one of a
        // pair) in each combination orthogonal to moving alike (Helmert's), the point still.
        let mut still: Vec<(c64, &Group, usize, Vec<f64>)> = vec![];
        for group in &self.groups {
            for k in 1..group.members.len() {
                let norm = ((k * (k + 1)) as f64).sqrt();
                let mix: Vec<f64> = (0..group.members.len())
                    .map(|m| match m.cmp(&k) {
                        std::cmp::Ordering::Less => 1.0 / norm,
                        std::cmp::Ordering::Equal => -(k as f64) / norm,
                        std::cmp::Ordering::Greater => 0.0,
                    })
                    .collect();
                for (j, &mu) in group.poles.mu.iter().enumerate() {
                    if mu.im >= 0.0 {
                        still.push((mu, group, j, mix.clone()));
                    }
                }
            }
        }
        let moving = roots.len();
        let kept = moving + still.len();
        // Per root: the point's motion `u` and `Z u`.
        let mut motion = Vec::with_capacity(moving);
        for &s in roots {
            let sums = self.sums(s);
            let (z, _) = self.impedance(s, &sums);
            let u = null_vector(point_matrix(&sums.g, &z))?;
            motion.push((u, std::array::from_fn::<c64, 3, _>(|d| z[d] * u[d])));
        }
        let mut shape = Mat::<c64>::zeros(sys.n, kept);
        // Each held system's part: its shapes times the coefficients `(. . q_j) / (s - mu_j)`,
        // at each of its starts.
        let mut part =
            |poles: &Poles, starts: &[usize], coefficient: &dyn Fn(usize, usize) -> c64| {
                let coef = Mat::<c64>::from_fn(poles.mu.len(), moving, |j, r| {
                    coefficient(j, r) * (roots[r] - poles.mu[j]).inv()
                });
                let block = &poles.shape * &coef;
                for &start in starts {
                    for r in 0..moving {
                        for i in 0..block.nrows() {
                            shape[(start + i, r)] = block[(i, r)];
                        }
                    }
                }
            };
        for group in &self.groups {
            let d = group.direction;
            let (k, c) = (sys.contact_stiffness_n_m[d], sys.contact_damping_n_s_m[d]);
            let starts: Vec<usize> = group
                .members
                .iter()
                .map(|&s| sys.strands[s].start)
                .collect();
            part(&group.poles, &starts, &|j, r| {
                let delta = c64::new(k, 0.0) + roots[r] * c;
                delta * motion[r].0[d] * group.poles.at[j][0]
            });
        }
        let board = &self.board;
        part(board, &[sys.board_start], &|j, r| {
            let zu = motion[r].1;
            board.at[j][0] * zu[0] + board.at[j][1] * zu[1] + board.at[j][2] * zu[2]
        });
        for (r, (_, group, j, mix)) in still.iter().enumerate() {
            for (&s, &x) in group.members.iter().zip(mix) {
                let start = sys.strands[s].start;
                for i in 0..group.poles.shape.nrows() {
                    shape[(start + i, moving + r)] = group.poles.shape[(i, *j)] * x;
                }
            }
        }
        let lambda: Vec<c64> = roots
            .iter()
            .copied()
            .chain(still.iter().map(|m| m.0))
            .collect();
        let weight = lambda
            .iter()
            .map(|s| if s.im == 0.0 { 1.0 } else { 2.0 })
            .collect();
        Modal::scaled(lambda, weight, shape, c).ok()
    }
}

/// `I - G Z` (`Z` diagonal), whose null vectors are the bridge point's motions.
fn point_matrix(g: &[[c64; 3]; 3], z: &[c64; 3]) -> [[c64; 3]; 3] {
    std::array::from_fn(|a| std::array::from_fn(|b| f64::from(u8::from(a == b)) - g[a][b] * z[b]))
}

/// `tr(M^-1 D)` for 3×3 complex `M` and `D`, by Gaussian elimination with partial pivoting.
fn trace_of_solve(mut m: [[c64; 3]; 3], mut d: [[c64; 3]; 3]) -> c64 {
    for col in 0..3 {
        let pivot = (col..3)
            .max_by(|&a, &b| m[a][col].norm().total_cmp(&m[b][col].norm()))
            .unwrap_or(col);
        m.swap(col, pivot);
        d.swap(col, pivot);
        let inv = m[col][col].inv();
        for row in col + 1..3 {
            let f = m[row][col] * inv;
            for k in col..3 {
                let x = m[col][k];
                m[row][k] -= f * x;
            }
            for k in 0..3 {
                let x = d[col][k];
                d[row][k] -= f * x;
            }
        }
    }
    // Back substitution for the diagonal of `X = M^-1 D` only needs the whole of `X`'s columns.
    let mut x = [[c64::new(0.0, 0.0); 3]; 3];
    for k in 0..3 {
        for row in (0..3).rev() {
            let mut acc = d[row][k];
            for j in row + 1..3 {
                acc -= m[row][j] * x[j][k];
            }
            x[row][k] = acc / m[row][row];
        }
    }
    x[0][0] + x[1][1] + x[2][2]
}

/// A vector `u` with `M u = 0` for a 3×3 `M` of rank 2: the (unconjugated) cross product of the
/// two rows that are furthest from parallel. None if `M` has rank below 2 (a double root: its
/// shapes are not one point motion).
fn null_vector(m: [[c64; 3]; 3]) -> Option<[c64; 3]> {
    let cross = |a: [c64; 3], b: [c64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let size = |v: &[c64; 3]| v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt();
    let best = [cross(m[0], m[1]), cross(m[0], m[2]), cross(m[1], m[2])]
        .into_iter()
        .max_by(|a, b| size(a).total_cmp(&size(b)))?;
    let rows: f64 = m.iter().map(size).fold(0.0, f64::max);
    (size(&best) > 1e-13 * rows * rows).then_some(best)
}

/// `modal` if every mode's residual `(s^2 + s C + K) q` is at the rounding level of its terms
/// and the modes rebuild a force and a displacement.
fn checked(modal: Modal, k: &[f64], c: &[f64]) -> Option<Modal> {
    const RESIDUAL: f64 = 1e-10;
    const REBUILT: f64 = 1e-7;
    let n = modal.n;
    let kept = modal.lambda.len();
    let (stiffness, damping) = (
        Mat::<f64>::from_fn(n, n, |i, j| k[i * n + j]),
        Mat::<f64>::from_fn(n, n, |i, j| c[i * n + j]),
    );
    let (re, im) = real_parts(&modal.shape);
    let (kre, kim, cre, cim) = (
        &stiffness * &re,
        &stiffness * &im,
        &damping * &re,
        &damping * &im,
    );
    for j in 0..kept {
        let s = modal.lambda[j];
        // Each of the three terms' size, against which the residual is rounding.
        let (mut residual, mut size) = (0.0f64, [0.0f64; 3]);
        for i in 0..n {
            let q = modal.shape[(i, j)];
            let terms = [
                q * s * s,
                c64::new(cre[(i, j)], cim[(i, j)]) * s,
                c64::new(kre[(i, j)], kim[(i, j)]),
            ];
            residual = residual.max((terms[0] + terms[1] + terms[2]).norm());
            for (size, t) in size.iter_mut().zip(terms) {
                *size = size.max(t.norm());
            }
        }
        let scale: f64 = size.iter().sum();
        if residual.is_nan() || residual > RESIDUAL * scale {
            return None;
        }
    }
    // A force `[0; b]` and a displacement `[b; 0]` rebuilt from the modes (`x = [q; s q]`, the
    // left vector `[(s + C) q; q]`), each mode with its conjugate partner: each of the four
    // halves against the largest of its terms, the scale of its rounding.
    let b: Vec<f64> = (0..n)
        .map(|i| ((i * 7919 % 113) as f64 / 56.0) - 1.0)
        .collect();
    let cb: Vec<f64> = (0..n)
        .map(|i| (0..n).map(|j| c[i * n + j] * b[j]).sum())
        .collect();
    let mut sums = vec![[0.0f64; 4]; n];
    let mut sizes = [0.0f64; 4];
    for j in 0..kept {
        let (s, w) = (modal.lambda[j], modal.weight[j]);
        let (mut by_force, mut by_displacement) = (c64::new(0.0, 0.0), c64::new(0.0, 0.0));
        for i in 0..n {
            let q = modal.shape[(i, j)];
            by_force += q * b[i];
            by_displacement += q * (s * b[i] + cb[i]);
        }
        for (i, sum) in sums.iter_mut().enumerate() {
            let q = modal.shape[(i, j)];
            let terms = [
                q * by_force,
                q * s * by_force,
                q * by_displacement,
                q * s * by_displacement,
            ];
            for (k, t) in terms.iter().enumerate() {
                sum[k] += w * t.re;
                sizes[k] = sizes[k].max(w * t.norm());
            }
        }
    }
    let error = (0..4)
        .map(|k| {
            let want = |i: usize| if k == 1 || k == 2 { b[i] } else { 0.0 };
            (0..n)
                .map(|i| (sums[i][k] - want(i)).abs())
                .fold(0.0, f64::max)
                / sizes[k]
        })
        .fold(0.0, f64::max);
    (error <= REBUILT).then_some(modal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::exact::test_numbers;
    use crate::engine::modal::solved_response;
    use std::f64::consts::PI;

    /// A small key: three strings of 6 T, 3 L and 6 P modes (the second and third `sharp`
    /// apart in T and P, alike in L; T and P damped densely, as by a duplex felt) on stiff contact
    /// springs to 8 board modes, its numbers drawn from a seeded generator.
    fn small_key(sharp: f64) -> BridgeSystem {
        let mut x = test_numbers(7);
        let modes = [6, 3, 6];
        let mut strands = vec![];
        let mut start = 0;
        for s in 0..3 {
            for (d, &m) in modes.iter().enumerate() {
                let tuned = if d == 1 { 12.0 } else { 1.0 + sharp * s as f64 };
                let omega: Vec<f64> = (1..=m)
                    .map(|j| 2.0 * PI * 110.0 * j as f64 * tuned)
                    .collect();
                let felt: Vec<f64> = (0..m).map(|_| 2.0 + x()).collect();
                let mut damping = vec![0.0; m * m];
                for i in 0..m {
                    damping[i * m + i] = 2e-3 * omega[i];
                    if d != 1 {
                        for j in 0..m {
                            damping[i * m + j] += 0.5 * felt[i] * felt[j];
                        }
                    }
                }
                strands.push(Strand {
                    direction: d,
                    start,
                    omega2: omega.iter().map(|w| w * w).collect(),
                    damping,
                    at_bridge: (1..=m)
                        .map(|j| 20.0 * (0.95 * PI * j as f64).sin())
                        .collect(),
                });
                start += m;
            }
        }
        let board: Vec<f64> = (0..8)
            .map(|i| 2.0 * PI * (90.0 + 260.0 * i as f64))
            .collect();
        BridgeSystem {
            n: start + board.len(),
            strands,
            board_start: start,
            board_omega2: board.iter().map(|w| w * w).collect(),
            board_damping: board.iter().map(|w| 0.04 * w).collect(),
            board_at_point: std::array::from_fn(|_| board.iter().map(|_| 0.6 * x()).collect()),
            contact_stiffness_n_m: [2e6, 8e6, 1e6],
            contact_damping_n_s_m: [30.0, 60.0, 20.0],
        }
    }

    /// The board's motion at the point in T per unit force on the first string's modes
    /// (`c^T (K - omega^2 + i omega C)^-1 b`), from the modes and by a direct solve.
    fn responses(system: &BridgeSystem, modal: &Modal, omega: f64) -> (c64, c64) {
        let (k, damping) = system.dense();
        let n = system.n;
        let (mut c, mut b) = (vec![0.0; n], vec![0.0; n]);
        for (i, x) in system.board_at_point[0].iter().enumerate() {
            c[system.board_start + i] = *x;
        }
        for (i, x) in b
            .iter_mut()
            .take(system.strands[0].omega2.len())
            .enumerate()
        {
            *x = (0.3 * (i + 1) as f64).sin();
        }
        (
            modal.response(&c, &b, omega),
            solved_response(&k, &damping, &c, &b, omega),
        )
    }

    #[test]
    fn a_small_key_through_its_bridge_has_its_dense_modes_and_response() {
        // Detuned strings, and strings alike in every direction (whose modes against one
        // another leave the bridge still): every eigenvalue against the dense eigen-solve's
        // (agreeing to ~3e-13 of |lambda|, the limit 3e-12), and the board's response at the
        // point to a force on a string against a direct solve (~1e-11, the stiff springs'
        // conditioning; the limit 1e-10).
        for sharp in [0.013, 0.0] {
            let system = small_key(sharp);
            let (k, c) = system.dense();
            let modal = system.modes(&k, &c).expect("solved through the bridge");
            let dense = Modal::dense(&k, &c, system.n).unwrap();
            assert_eq!(modal.lambda.len(), dense.lambda.len());
            let mut eigen: f64 = 0.0;
            for l in &dense.lambda {
                let near = modal
                    .lambda
                    .iter()
                    .map(|m| (m - l).norm())
                    .fold(f64::MAX, f64::min);
                eigen = eigen.max(near / l.norm());
            }
            let (mut response, mut eigen_solve) = (0.0f64, 0.0f64);
            for f_hz in [60.0, 150.0, 330.0, 700.0, 1500.0] {
                let (got, want) = responses(&system, &modal, 2.0 * PI * f_hz);
                let (by_dense, _) = responses(&system, &dense, 2.0 * PI * f_hz);
                response = response.max((got - want).norm() / want.norm());
                eigen_solve = eigen_solve.max((by_dense - want).norm() / want.norm());
            }
            println!(
                "strings {sharp} apart: eigenvalues {eigen:.1e}, response {response:.1e} \
                 (the dense eigen-solve's modes: {eigen_solve:.1e})"
            );
            assert!(eigen < 3e-12 && response < 1e-10, "{eigen:e} {response:e}");
        }
    }

    #[test]
    fn the_checks_refuse_a_mode_missing_or_misplaced() {
        // The solve's own modes pass; without one mode the modes no longer rebuild a force, and
        // with one eigenvalue moved by 1e-8 of itself its residual is ~1e-8 of its terms (the
        // limit 1e-10).
        let system = small_key(0.013);
        let (k, c) = system.dense();
        let modal = system.modes(&k, &c).unwrap();
        let copy = |drop: usize, moved: usize| {
            let keep: Vec<usize> = (0..modal.lambda.len()).filter(|&m| m != drop).collect();
            Modal {
                n: modal.n,
                lambda: keep
                    .iter()
                    .map(|&m| modal.lambda[m] * if m == moved { 1.0 + 1e-8 } else { 1.0 })
                    .collect(),
                weight: keep.iter().map(|&m| modal.weight[m]).collect(),
                shape: Mat::from_fn(modal.n, keep.len(), |i, j| modal.shape[(i, keep[j])]),
                padded: modal.padded,
            }
        };
        let none = usize::MAX;
        assert!(checked(copy(none, none), &k, &c).is_some());
        assert!(checked(copy(3, none), &k, &c).is_none(), "a mode missing");
        assert!(
            checked(copy(none, 3), &k, &c).is_none(),
            "an eigenvalue moved"
        );
    }
}
