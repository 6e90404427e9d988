//! Exact-to-double-double Gram matrix of the DMDc feature matrix and its Cholesky factor.
//!
//! Why: the DMDc regression needs the triangular factor R of the feature matrix F
//! (`hankel::feature_matrix`, N × C). On smooth, noise-free flight data cond(F) ≈ 1e8–1e9,
//! so the f64 Gram FᵀF (cond ≈ 1e17) cannot be factored and a Householder QR of F — O(N C²)
//! at Householder speed — was needed. This module instead forms G = FᵀF in double-double
//! arithmetic (≈ 106-bit significand, unit roundoff u² ≈ 1.2e-32) and factors it with a
//! double-double Cholesky, G = Rᵀ R. The squared condition number is then harmless: the
//! Cholesky backward error ≈ C·u²·‖G‖ perturbs σ_min(F)² by a relative C·u²·cond(F)² ≈ 1e-15
//! at cond(F) = 1e8, so R rounded to f64 is as accurate as (in fact more accurate than) the
//! Householder R, whose backward error is ≈ u‖F‖.
//!
//! Speed: F is block-Hankel. With column (lag ℓ, state i) holding x_i[k − ℓ] over the sample
//! window k ∈ [k₀, k₁] (the target x_{k+1} is lag −1), the entries along a lag diagonal obey
//!   S(ℓ₁+1, ℓ₂+1) = S(ℓ₁, ℓ₂) + x_i[k₀−1−ℓ₁] x_j[k₀−1−ℓ₂] − x_i[k₁−ℓ₁] x_j[k₁−ℓ₂]
//! (the window slides back by one sample), so only the entries involving the lag −1 columns,
//! the inputs and the constant are full dot products: O(N·C·(n+m+1)) instead of O(N·C²).
//! Each dot product is an error-free-transformation sum (Ogita, Rump, Oishi 2005, "Dot2":
//! TwoProd by FMA, TwoSum per term, kept as hi + lo), each recurrence step adds two exact
//! products in double-double, so every entry is accurate to ≈ u²·Σ|a_k b_k|.
//! The kernels run with AVX2 + FMA when the CPU has them (runtime detection) and with
//! Dekker's splitting otherwise.

use super::hankel::Trajectory;

/// A double-double number hi + lo with |lo| ≤ ulp(hi)/2.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Dd {
    /// Leading part (the f64 rounding of the value).
    pub hi: f64,
    /// Trailing part.
    pub lo: f64,
}

/// a + b = s + e exactly (Knuth).
#[inline(always)]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// a + b = s + e exactly, for |a| ≥ |b| (Dekker).
#[inline(always)]
fn fast_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

/// Error-free product a·b = p + e.
trait TwoProd {
    fn two_prod(a: f64, b: f64) -> (f64, f64);
}

/// Hardware fused multiply-add (only used inside `target_feature(enable = "fma")` code on
/// x86-64, and on AArch64 where FMA is part of the base ISA).
struct Fma;
impl TwoProd for Fma {
    #[inline(always)]
    fn two_prod(a: f64, b: f64) -> (f64, f64) {
        let p = a * b;
        (p, a.mul_add(b, -p))
    }
}

/// Dekker's splitting (no FMA needed). Inputs here are data values far from overflow.
struct Split;
impl Split {
    #[inline(always)]
    fn split(a: f64) -> (f64, f64) {
        let t = 134_217_729.0 * a; // 2^27 + 1
        let hi = t - (t - a);
        (hi, a - hi)
    }
}
impl TwoProd for Split {
    #[inline(always)]
    fn two_prod(a: f64, b: f64) -> (f64, f64) {
        let p = a * b;
        let (ah, al) = Self::split(a);
        let (bh, bl) = Self::split(b);
        (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
    }
}

impl Dd {
    #[inline(always)]
    fn from_parts(hi: f64, lo: f64) -> Self {
        let (hi, lo) = fast_two_sum(hi, lo);
        Self { hi, lo }
    }

    /// self + other (accurate double-double addition).
    #[inline(always)]
    fn add(self, o: Dd) -> Dd {
        let (s, e) = two_sum(self.hi, o.hi);
        let (t, f) = two_sum(self.lo, o.lo);
        let (s, e) = fast_two_sum(s, e + t);
        Dd::from_parts(s, e + f)
    }

    #[inline(always)]
    fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }

    /// self + a·b with the product exact.
    #[inline(always)]
    fn add_prod<P: TwoProd>(self, a: f64, b: f64) -> Dd {
        let (p, e) = P::two_prod(a, b);
        self.add(Dd { hi: p, lo: e })
    }

    /// self · o (double-double product, relative error ≈ 4u²).
    #[inline(always)]
    fn mul<P: TwoProd>(self, o: Dd) -> Dd {
        let (p, e) = P::two_prod(self.hi, o.hi);
        Dd::from_parts(p, e + (self.hi * o.lo + self.lo * o.hi))
    }

    /// self / o (one Newton-like correction of the f64 quotient).
    #[inline(always)]
    fn div<P: TwoProd>(self, o: Dd) -> Dd {
        let q1 = self.hi / o.hi;
        let r = self.add(Dd { hi: q1, lo: 0.0 }.mul::<P>(o).neg());
        let q2 = r.hi / o.hi;
        let r = r.add(Dd { hi: q2, lo: 0.0 }.mul::<P>(o).neg());
        let q3 = r.hi / o.hi;
        let (q1, q2) = fast_two_sum(q1, q2);
        Dd::from_parts(q1, q2 + q3)
    }

    /// √self for self > 0.
    #[inline(always)]
    fn sqrt<P: TwoProd>(self) -> Dd {
        let s = self.hi.sqrt();
        let r = self.add(Dd { hi: s, lo: 0.0 }.mul::<P>(Dd { hi: s, lo: 0.0 }).neg());
        Dd::from_parts(s, r.hi / (2.0 * s))
    }
}

/// Lanes of the vectorised dot products (two AVX2 registers).
const LANES: usize = 8;

/// Σ a_k b_k as a double-double (Dot2 with LANES independent accumulators).
#[inline(always)]
fn dot_dd<P: TwoProd>(a: &[f64], b: &[f64]) -> Dd {
    let len = a.len().min(b.len());
    let (a, b) = (&a[..len], &b[..len]);
    let mut hi = [0.0; LANES];
    let mut lo = [0.0; LANES];
    let ca = a.chunks_exact(LANES);
    let cb = b.chunks_exact(LANES);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..LANES {
            let (p, e) = P::two_prod(x[l], y[l]);
            let (s, f) = two_sum(hi[l], p);
            hi[l] = s;
            lo[l] += e + f;
        }
    }
    // Merge the lanes and the tail in the same Dot2 fashion (TwoSum on the leading parts).
    let (mut s, mut c) = (0.0, 0.0);
    for l in 0..LANES {
        let (t, f) = two_sum(s, hi[l]);
        s = t;
        c += f + lo[l];
    }
    for (x, y) in ra.iter().zip(rb) {
        let (p, e) = P::two_prod(*x, *y);
        let (t, f) = two_sum(s, p);
        s = t;
        c += e + f;
    }
    Dd::from_parts(s, c)
}

/// Σ_k (ah_k + al_k)(bh_k + bl_k) as a double-double (products to ≈ u² relative).
#[inline(always)]
fn dot_dd2<P: TwoProd>(ah: &[f64], al: &[f64], bh: &[f64], bl: &[f64]) -> Dd {
    let len = ah.len();
    let (al, bh, bl) = (&al[..len], &bh[..len], &bl[..len]);
    let mut hi = [0.0; LANES];
    let mut lo = [0.0; LANES];
    let full = len - len % LANES;
    let chunks = ah[..full]
        .chunks_exact(LANES)
        .zip(al[..full].chunks_exact(LANES))
        .zip(
            bh[..full]
                .chunks_exact(LANES)
                .zip(bl[..full].chunks_exact(LANES)),
        );
    for ((xh, xl), (yh, yl)) in chunks {
        for l in 0..LANES {
            let (p, e) = P::two_prod(xh[l], yh[l]);
            let (s, f) = two_sum(hi[l], p);
            hi[l] = s;
            lo[l] += e + f + (xh[l] * yl[l] + xl[l] * yh[l]);
        }
    }
    let (mut s, mut c) = (0.0, 0.0);
    for l in 0..LANES {
        let (t, f) = two_sum(s, hi[l]);
        s = t;
        c += f + lo[l];
    }
    for k in full..len {
        let (p, e) = P::two_prod(ah[k], bh[k]);
        let (t, f) = two_sum(s, p);
        s = t;
        c += e + f + (ah[k] * bl[k] + al[k] * bh[k]);
    }
    Dd::from_parts(s, c)
}

/// Gram matrix FᵀF of `feature_matrix(traj, q_max, affine, input_mean)` in double-double,
/// C × C row-major (symmetric, both triangles filled). Same column layout as F.
pub(crate) fn feature_gram(
    traj: &Trajectory<'_>,
    q_max: usize,
    affine: bool,
    input_mean: &[f64],
) -> Vec<Dd> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the enabled features (checked just above).
            return unsafe { feature_gram_fma(traj, q_max, affine, input_mean) };
        }
    }
    // AArch64 (the Jetson) always has a fused multiply-add.
    #[cfg(target_arch = "aarch64")]
    {
        return feature_gram_impl::<Fma>(traj, q_max, affine, input_mean);
    }
    #[allow(unreachable_code)]
    feature_gram_impl::<Split>(traj, q_max, affine, input_mean)
}

/// [`feature_gram`] compiled for AVX2 + FMA.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn feature_gram_fma(
    traj: &Trajectory<'_>,
    q_max: usize,
    affine: bool,
    input_mean: &[f64],
) -> Vec<Dd> {
    feature_gram_impl::<Fma>(traj, q_max, affine, input_mean)
}

#[inline(always)]
fn feature_gram_impl<P: TwoProd>(
    traj: &Trajectory<'_>,
    q: usize,
    affine: bool,
    input_mean: &[f64],
) -> Vec<Dd> {
    let (n, m, len) = (traj.n, traj.m, traj.len);
    let k0 = q - 1;
    let k1 = len - 2;
    let rows = k1 + 1 - k0;
    let lead = m + usize::from(affine);
    let cols = lead + n * q + n;
    // Per-state series, contiguous.
    let xs: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..len).map(|t| traj.x[t * n + i]).collect())
        .collect();
    // Lead columns over the window (inputs minus mean — the same f64 values as F — then 1).
    let mut leads: Vec<Vec<f64>> = (0..m)
        .map(|j| {
            (k0..=k1)
                .map(|k| traj.u[k * m + j] - input_mean[j])
                .collect()
        })
        .collect();
    if affine {
        leads.push(vec![1.0; rows]);
    }
    // State column with lag index L = ℓ + 1 (L = 0: target) holds x_i[k + 1 − L].
    let window = |l: usize, i: usize| &xs[i][k0 + 1 - l..k1 + 2 - l];
    let col_of = |l: usize, i: usize| {
        if l == 0 {
            lead + n * q + i
        } else {
            lead + (l - 1) * n + i
        }
    };
    let mut g = vec![Dd::default(); cols * cols];
    let set = |g: &mut Vec<Dd>, a: usize, b: usize, v: Dd| {
        g[a * cols + b] = v;
        g[b * cols + a] = v;
    };
    // Lead × lead and lead × state: direct dot products.
    for a in 0..lead {
        for b in a..lead {
            let v = dot_dd::<P>(&leads[a], &leads[b]);
            set(&mut g, a, b, v);
        }
        if affine && a == m {
            // Constant × state: window sums, which slide like the lag diagonals:
            // sum(L + 1) = sum(L) + x_i[k₀ − L] − x_i[k₁ + 1 − L].
            for i in 0..n {
                let mut v = dot_dd::<P>(&leads[a], window(0, i));
                set(&mut g, a, col_of(0, i), v);
                for l in 1..=q {
                    v = v
                        .add(Dd {
                            hi: xs[i][k0 + 1 - l],
                            lo: 0.0,
                        })
                        .add(Dd {
                            hi: -xs[i][k1 + 2 - l],
                            lo: 0.0,
                        });
                    set(&mut g, a, col_of(l, i), v);
                }
            }
            continue;
        }
        for l in 0..=q {
            for i in 0..n {
                let v = dot_dd::<P>(&leads[a], window(l, i));
                set(&mut g, a, col_of(l, i), v);
            }
        }
    }
    // State × state over idx = L·n + i, idx_a ≤ idx_b: base row L_a = 0 by dot products,
    // the rest by the sliding-window recurrence from (idx_a − n, idx_b − n).
    let ns = n * (q + 1);
    let mut s = vec![Dd::default(); ns * ns];
    for ia in 0..ns {
        let (la, i) = (ia / n, ia % n);
        for ib in ia..ns {
            let (lb, j) = (ib / n, ib % n);
            let v = if la == 0 {
                dot_dd::<P>(window(0, i), window(lb, j))
            } else {
                // New window starts one sample earlier and ends one earlier.
                s[(ia - n) * ns + ib - n]
                    .add_prod::<P>(xs[i][k0 + 1 - la], xs[j][k0 + 1 - lb])
                    .add_prod::<P>(-xs[i][k1 + 2 - la], xs[j][k1 + 2 - lb])
            };
            s[ia * ns + ib] = v;
            set(&mut g, col_of(la, i), col_of(lb, j), v);
        }
    }
    g
}

/// Upper-triangular R (f64, C × C row-major) with RᵀR = G, by a double-double Cholesky.
///
/// `None` when a pivot of the first C − `targets` columns (the regressors) is not positive or
/// below `1e-14` of the largest regressor pivot: the data are (numerically) rank deficient and
/// the caller falls back to a rank-revealing-safe Householder QR. Pivots of the last
/// `targets` columns are residual norms and may vanish (an exact fit); they are clamped at 0.
pub(crate) fn cholesky_dd(g: &[Dd], c: usize, targets: usize) -> Option<Vec<f64>> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the enabled features (checked just above).
            return unsafe { cholesky_fma(g, c, targets) };
        }
    }
    #[cfg(target_arch = "aarch64")]
    {
        return cholesky_impl::<Fma>(g, c, targets);
    }
    #[allow(unreachable_code)]
    cholesky_impl::<Split>(g, c, targets)
}

/// [`cholesky_dd`] compiled for AVX2 + FMA.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn cholesky_fma(g: &[Dd], c: usize, targets: usize) -> Option<Vec<f64>> {
    cholesky_impl::<Fma>(g, c, targets)
}

#[inline(always)]
fn cholesky_impl<P: TwoProd>(g: &[Dd], c: usize, targets: usize) -> Option<Vec<f64>> {
    // Lower factor L (= Rᵀ), rows contiguous, hi and lo parts apart for the dot kernel.
    let mut lh = vec![0.0; c * c];
    let mut ll = vec![0.0; c * c];
    let regressors = c - targets;
    let mut max_pivot = 0.0_f64;
    for j in 0..c {
        let rj = j * c;
        let dot = dot_dd2::<P>(
            &lh[rj..rj + j],
            &ll[rj..rj + j],
            &lh[rj..rj + j],
            &ll[rj..rj + j],
        );
        let d = g[rj + j].add(dot.neg());
        let pivot = if j < regressors {
            if !(d.hi > 0.0 && d.hi.is_finite()) {
                return None;
            }
            let p = d.sqrt::<P>();
            max_pivot = max_pivot.max(p.hi);
            p
        } else if d.hi > 0.0 && d.hi.is_finite() {
            d.sqrt::<P>()
        } else {
            Dd::default()
        };
        lh[rj + j] = pivot.hi;
        ll[rj + j] = pivot.lo;
        if pivot.hi == 0.0 {
            continue;
        }
        for i in j + 1..c {
            let ri = i * c;
            let dot = dot_dd2::<P>(
                &lh[ri..ri + j],
                &ll[ri..ri + j],
                &lh[rj..rj + j],
                &ll[rj..rj + j],
            );
            let v = g[ri + j].add(dot.neg()).div::<P>(pivot);
            lh[ri + j] = v.hi;
            ll[ri + j] = v.lo;
        }
    }
    let min_pivot = (0..regressors)
        .map(|j| lh[j * c + j])
        .fold(f64::INFINITY, f64::min);
    // Every regressor pivot is positive and finite here, so the comparison is total.
    if min_pivot <= 1e-14 * max_pivot {
        return None;
    }
    // R = Lᵀ, rounded to f64 (hi is the rounding of hi + lo).
    let mut r = vec![0.0; c * c];
    for i in 0..c {
        for j in 0..=i {
            r[j * c + i] = lh[i * c + j];
        }
    }
    Some(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sysid::hankel::feature_matrix;

    /// A seeded, wiggly 2-state / 1-input series (values of mixed sign and size).
    fn series(len: usize) -> (Vec<f64>, Vec<f64>) {
        let x = (0..2 * len)
            .map(|k| {
                (0.37 * k as f64).sin() * 3.0 + (0.011 * k as f64).cos() + 0.1 * (k % 7) as f64
            })
            .collect();
        let u = (0..len)
            .map(|k| (0.23 * k as f64).cos() + 0.5 * (k % 5) as f64 - 1.0)
            .collect();
        (x, u)
    }

    /// The recurrence Gram equals FᵀF formed from the explicit feature matrix (f64 product,
    /// error ≤ N·u·|F|ᵀ|F|), for every offset layout, and the FMA and Dekker kernels agree.
    #[test]
    fn hankel_gram_matches_explicit_product() {
        let (x, u) = series(300);
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        for (q, affine, mean) in [
            (7, true, 0.0),
            (7, false, 0.4),
            (1, true, 0.0),
            (12, false, 0.0),
        ] {
            let g = feature_gram(&traj, q, affine, &[mean]);
            let f = feature_matrix(&traj, q, affine, &[mean]);
            let c = f.ncols();
            assert_eq!(g.len(), c * c);
            let split = feature_gram_impl::<Split>(&traj, q, affine, &[mean]);
            for a in 0..c {
                for b in 0..c {
                    let (mut exact, mut abs) = (0.0, 0.0);
                    for k in 0..f.nrows() {
                        exact += f[(k, a)] * f[(k, b)];
                        abs += (f[(k, a)] * f[(k, b)]).abs();
                    }
                    let v = g[a * c + b];
                    assert!(
                        (v.hi - exact).abs() <= 1e-13 * abs.max(1e-300),
                        "entry ({a}, {b}) q {q}: {} vs {exact}",
                        v.hi
                    );
                    let w = split[a * c + b];
                    assert!(
                        (v.hi - w.hi).abs() <= 4.0 * f64::EPSILON * abs,
                        "kernels differ"
                    );
                }
            }
        }
    }

    /// RᵀR reproduces the Gram, R is upper triangular with a positive diagonal, and a
    /// rank-deficient Gram is declined.
    #[test]
    fn cholesky_reproduces_gram_and_declines_rank_deficiency() {
        let (x, u) = series(300);
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        let g = feature_gram(&traj, 5, true, &[0.0]);
        let c = 1 + 1 + 2 * 5 + 2;
        let r = cholesky_dd(&g, c, 2).unwrap();
        for i in 0..c {
            assert!(r[i * c + i] > 0.0);
            for j in 0..i {
                assert_eq!(r[i * c + j], 0.0);
            }
        }
        for a in 0..c {
            for b in 0..c {
                let rtr: f64 = (0..c).map(|k| r[k * c + a] * r[k * c + b]).sum();
                let scale = (g[a * c + a].hi * g[b * c + b].hi).sqrt();
                assert!((rtr - g[a * c + b].hi).abs() <= 1e-13 * scale);
            }
        }
        // A constant input duplicates the constant column: rank deficient.
        let flat = vec![2.0; 300];
        let traj = Trajectory::new(&x, 2, &flat, 1).unwrap();
        let g = feature_gram(&traj, 5, true, &[0.0]);
        assert!(cholesky_dd(&g, c, 2).is_none());
    }
}
