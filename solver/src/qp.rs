//! The window QP's engine: a dense box-constrained QP solved by a primal
//! active-set method, and the clamp of a gradient to the amplitude limit.
//! Shared by the refinement (`refine`) and the explicit tier (`explicit`).

/// Dense box-constrained QP `min 1/2 x'Hx + g'x, lo <= x <= hi` (lo <= 0 <= hi),
/// solved by a primal active-set method from x = 0.
#[derive(Debug, Clone)]
pub struct BoxQp<const N: usize> {
    pub h: [[f64; N]; N],
    pub g: [f64; N],
    pub lo: [f64; N],
    pub hi: [f64; N],
    pub x: [f64; N],
    /// -1 at lower bound, +1 at upper bound, 0 free.
    pub active: [i8; N],
    chol: [[f64; N]; N],
    /// 1 / chol[r][r]: the substitutions multiply instead of divide.
    inv_diag: [f64; N],
    /// Leading rows of `chol` still valid for the current free set: rows
    /// above the first changed free position depend only on the leading
    /// block of H, so they are kept.
    factored: usize,
    rhs: [f64; N],
    newton: [f64; N],
    free: [usize; N],
    /// Active-set iterations allowed (hard cap).
    max_iterations: usize,
    /// Multipliers below this count as zero.
    multiplier_tolerance: f64,
}

impl<const N: usize> BoxQp<N> {
    /// An empty QP solved with at most `max_iterations` active-set
    /// iterations; multipliers within `multiplier_tolerance` of zero count
    /// as zero.
    pub const fn new(max_iterations: usize, multiplier_tolerance: f64) -> BoxQp<N> {
        BoxQp {
            h: [[0.0; N]; N],
            g: [0.0; N],
            lo: [0.0; N],
            hi: [0.0; N],
            x: [0.0; N],
            active: [0; N],
            chol: [[0.0; N]; N],
            inv_diag: [0.0; N],
            factored: 0,
            rhs: [0.0; N],
            newton: [0.0; N],
            free: [0; N],
            max_iterations,
            multiplier_tolerance,
        }
    }

    /// The iteration cap.
    pub const fn max_iterations(&self) -> usize {
        self.max_iterations
    }

    /// Returns (iterations, converged). On the iteration bound, `x` is the
    /// last feasible iterate (always within the box).
    pub fn solve(&mut self) -> (u32, bool) {
        self.solve_from(&[0; N])
    }

    /// As `solve`, warm-started from the active set `active` (-1 lower,
    /// +1 upper, 0 free): the start puts active variables on their bounds
    /// and free ones at 0, which is feasible since lo <= 0 <= hi.
    pub fn solve_from(&mut self, active: &[i8; N]) -> (u32, bool) {
        let mut j = 0;
        while j < N {
            let a = active[j];
            self.active[j] = if a > 0 {
                1
            } else if a < 0 {
                -1
            } else {
                0
            };
            self.x[j] = if a > 0 {
                self.hi[j]
            } else if a < 0 {
                self.lo[j]
            } else {
                0.0
            };
            j += 1;
        }
        self.factored = 0;
        let mut iter = 0u32;
        while (iter as usize) < self.max_iterations {
            iter += 1;
            // Newton step on the free set with the active variables fixed.
            let nf = self.collect_free();
            if nf > 0 && !self.factor_free(nf) {
                return (iter, false);
            }
            self.factored = nf;
            self.free_newton_point(nf);
            // Ratio test from x towards the Newton point.
            let mut t = 1.0;
            let mut blocking = usize::MAX;
            let mut f = 0;
            while f < nf {
                let j = self.free[f];
                let d = self.newton[j] - self.x[j];
                if d > 0.0 && self.x[j] + d > self.hi[j] {
                    let tj = (self.hi[j] - self.x[j]) / d;
                    if tj < t {
                        t = tj;
                        blocking = j;
                    }
                } else if d < 0.0 && self.x[j] + d < self.lo[j] {
                    let tj = (self.lo[j] - self.x[j]) / d;
                    if tj < t {
                        t = tj;
                        blocking = j;
                    }
                }
                f += 1;
            }
            let mut f = 0;
            while f < nf {
                let j = self.free[f];
                self.x[j] += t * (self.newton[j] - self.x[j]);
                f += 1;
            }
            if blocking != usize::MAX {
                let up = self.newton[blocking] > self.x[blocking];
                self.x[blocking] = if up {
                    self.hi[blocking]
                } else {
                    self.lo[blocking]
                };
                self.active[blocking] = if up { 1 } else { -1 };
                self.keep_rows_before(blocking);
                continue;
            }
            // Optimal on this face: release the most wrong-signed multiplier.
            let mut worst = 0.0;
            let mut release = usize::MAX;
            let mut j = 0;
            while j < N {
                if self.active[j] != 0 {
                    let mut grad = self.g[j];
                    let mut c = 0;
                    while c < N {
                        grad += self.h[j][c] * self.x[c];
                        c += 1;
                    }
                    // At an upper bound the gradient must be <= 0, at a lower >= 0.
                    let wrong = if self.active[j] > 0 { grad } else { -grad };
                    if wrong > worst + self.multiplier_tolerance {
                        worst = wrong;
                        release = j;
                    }
                }
                j += 1;
            }
            if release == usize::MAX {
                return (iter, true);
            }
            self.active[release] = 0;
            self.keep_rows_before(release);
        }
        (iter, false)
    }

    /// Variable `j` joined or left the free set: Cholesky rows from its
    /// position in the (index-ordered) free list on must be recomputed.
    fn keep_rows_before(&mut self, j: usize) {
        let mut p = 0;
        let mut c = 0;
        while c < j {
            if self.active[c] == 0 {
                p += 1;
            }
            c += 1;
        }
        if p < self.factored {
            self.factored = p;
        }
    }

    fn collect_free(&mut self) -> usize {
        let mut nf = 0;
        let mut j = 0;
        while j < N {
            if self.active[j] == 0 {
                self.free[nf] = j;
                nf += 1;
            }
            j += 1;
        }
        nf
    }

    /// Cholesky of H restricted to the free set; false if not positive definite.
    fn factor_free(&mut self, nf: usize) -> bool {
        let mut r = self.factored;
        while r < nf {
            let mut c = 0;
            while c <= r {
                let mut s = self.h[self.free[r]][self.free[c]];
                let mut k = 0;
                while k < c {
                    s -= self.chol[r][k] * self.chol[c][k];
                    k += 1;
                }
                if r == c {
                    if s <= 0.0 || s.is_nan() {
                        return false;
                    }
                    self.chol[r][r] = libm::sqrt(s);
                    self.inv_diag[r] = 1.0 / self.chol[r][r];
                } else {
                    self.chol[r][c] = s * self.inv_diag[c];
                }
                c += 1;
            }
            r += 1;
        }
        true
    }

    /// newton = minimizer over the free variables with active ones at their bounds.
    fn free_newton_point(&mut self, nf: usize) {
        let mut j = 0;
        while j < N {
            self.newton[j] = self.x[j];
            j += 1;
        }
        let mut r = 0;
        while r < nf {
            let row = self.free[r];
            let mut s = -self.g[row];
            let mut c = 0;
            while c < N {
                if self.active[c] != 0 {
                    s -= self.h[row][c] * self.x[c];
                }
                c += 1;
            }
            self.rhs[r] = s;
            r += 1;
        }
        // Forward then backward substitution with L L'.
        let mut r = 0;
        while r < nf {
            let mut s = self.rhs[r];
            let mut k = 0;
            while k < r {
                s -= self.chol[r][k] * self.rhs[k];
                k += 1;
            }
            self.rhs[r] = s * self.inv_diag[r];
            r += 1;
        }
        let mut r = nf;
        while r > 0 {
            r -= 1;
            let mut s = self.rhs[r];
            let mut k = r + 1;
            while k < nf {
                s -= self.chol[k][r] * self.rhs[k];
                k += 1;
            }
            self.rhs[r] = s * self.inv_diag[r];
        }
        let mut r = 0;
        while r < nf {
            self.newton[self.free[r]] = self.rhs[r];
            r += 1;
        }
    }
}

/// A solver of the refinement's window QP: reads `h`, `g`, `lo`, `hi` of
/// `qp` and leaves its answer in `qp.x` (within the box even when it
/// fails; zero is). Returns (iterations, converged). The refinement's
/// engine is this crate's active-set method; benchmarks plug in others.
pub trait QpEngine<const N: usize> {
    fn solve(&mut self, qp: &mut BoxQp<N>) -> (u32, bool);
}

/// The primal active-set method of [`BoxQp`], from x = 0.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ActiveSet;

impl<const N: usize> QpEngine<N> for ActiveSet {
    #[inline]
    fn solve(&mut self, qp: &mut BoxQp<N>) -> (u32, bool) {
        qp.solve()
    }
}

/// `u` clamped to the amplitude limit [-u_max, u_max].
#[inline(always)]
pub fn clamp_u(u: f64, u_max: f64) -> f64 {
    if u > u_max {
        u_max
    } else if u < -u_max {
        -u_max
    } else {
        u
    }
}
