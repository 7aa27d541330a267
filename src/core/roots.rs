//! Roots of the cubic (or lower-degree) polynomials that volume impulses lead to.
//!
//! A tet whose vertices move by `s * d_i` has a volume that is a polynomial of degree at most
//! three in `s`. The impulse size is the smallest positive root of `V(s) - V0`, and the
//! neighbour clamp is the first place where a neighbour's volume crosses its floor. Both
//! questions are answered here in `f64`, by splitting `(0, hi]` at the critical points into
//! monotone pieces and bracketing the first sign change: no closed-form cubic formula, whose
//! cancellation fails on nearly degenerate coefficients.

/// A polynomial `c[0] + c[1] s + c[2] s^2 + c[3] s^3`.
pub type Cubic = [f64; 4];

/// Evaluates `c` at `s` (Horner).
#[inline]
pub fn eval(c: &Cubic, s: f64) -> f64 {
    ((c[3] * s + c[2]) * s + c[1]) * s + c[0]
}

/// Evaluates the derivative of `c` at `s`.
#[inline]
fn eval_derivative(c: &Cubic, s: f64) -> f64 {
    (3.0 * c[3] * s + 2.0 * c[2]) * s + c[1]
}

/// Whether roots where the polynomial only touches zero (without changing sign) count.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Touching {
    Count,
    Ignore,
}

/// The smallest root of `c` in `(0, hi]` (use `f64::INFINITY` for no bound), counting roots
/// where the polynomial touches zero without changing sign (double roots). `None` when there is
/// none, or when a coefficient is not finite.
#[cfg(test)]
pub(crate) fn smallest_positive_root(c: &Cubic, hi: f64) -> Option<f64> {
    first_root(c, hi, Touching::Count)
}

/// The smallest `s` in `(0, hi]` at which `c` changes sign. A polynomial that only touches zero
/// and turns back does not cross, so a floor that is reached but not passed does not count.
/// When `c(0) == 0` this asks where the polynomial first becomes negative from zero: `Some(0.0)`
/// when it decreases right away.
pub fn first_crossing(c: &Cubic, hi: f64) -> Option<f64> {
    if c[0] == 0.0 {
        // c(s) = s * q(s): the sign right after zero is the sign of q.
        let q = [c[1], c[2], c[3], 0.0];
        if q.iter().all(|&x| x == 0.0) {
            return None;
        }
        let leading = q.iter().copied().find(|&x| x != 0.0).unwrap_or(0.0);
        if leading < 0.0 {
            return Some(0.0);
        }
        return first_root(&q, hi, Touching::Ignore);
    }
    first_root(c, hi, Touching::Ignore)
}

/// Whether `c`, positive at zero, stays positive on `[0, hi]` by its coefficients alone: its
/// value there differs from `c[0]` by at most `|c1| hi + |c2| hi^2 + |c3| hi^3`. A few
/// operations against [`first_crossing`]'s search; `false` says nothing.
#[inline]
pub fn clear_of_zero(c: &Cubic, hi: f64) -> bool {
    let reach = hi * (c[1].abs() + hi * (c[2].abs() + hi * c[3].abs()));
    // The margin covers the rounding of the bound itself.
    c[0] > reach * (1.0 + 1e-9)
}

/// The root of `c` reached from `s = 0` while `c` moves monotonically towards zero: `c(0)` and
/// `c'(0)` have opposite signs and no critical point comes before the root. This is the root an
/// impulse may use. A polynomial that first moves away from zero, or turns before reaching it,
/// has its other positive roots only past a turning point, where the step has stopped being a
/// correction and is an artefact of the cubic; `None` then.
pub fn monotone_root(c: &Cubic) -> Option<f64> {
    if !c.iter().all(|x| x.is_finite())
        || c[0] == 0.0
        || c[1] == 0.0
        || (c[0] > 0.0) == (c[1] > 0.0)
    {
        return None;
    }
    // The usual case, a nearly linear volume: the linearised root `s0 = -c0 / c1` is almost the
    // root. If the derivative keeps the sign of `c1` on `[0, 2 s0]` (its other terms are smaller
    // than `|c1|` there) and the polynomial has changed sign by `2 s0`, the root in that bracket
    // is the monotone root: no turning point comes before it. This skips the scaling, the
    // Cauchy bound and the critical points, which cost more than the root itself.
    let s0 = -c[0] / c[1];
    let reach = 2.0 * s0;
    if reach * (2.0 * c[2].abs() + 3.0 * c[3].abs() * reach) < c[1].abs() {
        let p_reach = eval(c, reach);
        if p_reach == 0.0 {
            return Some(reach);
        }
        if (p_reach > 0.0) != (c[0] > 0.0) {
            return Some(bracketed_root(
                c,
                0.0,
                reach,
                c[0],
                s0,
                IMPULSE_RESIDUAL * c[0].abs(),
            ));
        }
    }
    monotone_root_general(c)
}

/// [`monotone_root`] without its shortcut for nearly linear polynomials.
fn monotone_root_general(c: &Cubic) -> Option<f64> {
    let scale = c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let c = [c[0] / scale, c[1] / scale, c[2] / scale, c[3] / scale];
    let degree = (1..4).rev().find(|&i| c[i] != 0.0)?;
    let lead = c[degree].abs();
    let bound = 1.0 + (0..degree).map(|i| c[i].abs() / lead).fold(0.0, f64::max);
    let (r1, r2) = derivative_roots(&c, degree);
    let turn = [r1, r2]
        .into_iter()
        .flatten()
        .filter(|&r| r > 0.0)
        .fold(bound, f64::min);
    let (p0, pt) = (c[0], eval(&c, turn));
    if pt == 0.0 {
        return Some(turn);
    }
    if p0 * pt < 0.0 {
        // Newton's first step from 0, the linearised root, is usually almost the root.
        return Some(bracketed_root(
            &c,
            0.0,
            turn,
            p0,
            -c[0] / c[1],
            IMPULSE_RESIDUAL * p0.abs(),
        ));
    }
    None
}

fn first_root(c: &Cubic, hi: f64, touching: Touching) -> Option<f64> {
    if !c.iter().all(|x| x.is_finite()) || hi.is_nan() || hi <= 0.0 {
        return None;
    }
    // Scale so that the largest coefficient is 1: keeps tolerances meaningful.
    let scale = c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if scale == 0.0 {
        return None;
    }
    let c = [c[0] / scale, c[1] / scale, c[2] / scale, c[3] / scale];
    let degree = (1..4).rev().find(|&i| c[i] != 0.0)?;

    // Cauchy's bound: every real root lies in [-bound, bound].
    let lead = c[degree].abs();
    let bound = 1.0 + (0..degree).map(|i| c[i].abs() / lead).fold(0.0, f64::max);
    let hi = hi.min(bound);

    // Critical points in (0, hi), sorted.
    let mut breaks = [0.0f64; 4];
    let mut n = 0;
    breaks[n] = 0.0;
    n += 1;
    let (r1, r2) = derivative_roots(&c, degree);
    for r in [r1, r2].into_iter().flatten() {
        if r > 0.0 && r < hi {
            breaks[n] = r;
            n += 1;
        }
    }
    if n == 3 && breaks[1] > breaks[2] {
        breaks.swap(1, 2);
    }
    breaks[n] = hi;
    n += 1;

    let magnitude = |s: f64| c[0].abs() + s * (c[1].abs() + s * (c[2].abs() + s * c[3].abs()));
    // The sign of the last non-zero value seen; a change of it is a crossing.
    let mut last_sign = sign(eval(&c, 0.0));
    for k in 0..n - 1 {
        let (a, b) = (breaks[k], breaks[k + 1]);
        let (pa, mut pb) = (eval(&c, a), eval(&c, b));
        // At a critical point, a value within rounding of zero is a zero: a double root
        // evaluated a hair below zero is a touch, not two crossings.
        if b < hi && pb.abs() <= 1e-14 * magnitude(b) {
            pb = 0.0;
        }
        if pb != 0.0 {
            let sb = sign(pb);
            if last_sign != 0.0 && sb != last_sign {
                // pa == 0 here only at a zero that the previous piece ended on: the crossing is there.
                return Some(if pa == 0.0 {
                    a
                } else {
                    bracketed_root(&c, a, b, pa, a - pa * (b - a) / (pb - pa), 0.0)
                });
            }
            last_sign = sb;
        } else if touching == Touching::Count && b > 0.0 {
            return Some(b);
        }
    }
    None
}

fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Real roots of the derivative, smaller first (`None` where there is none).
fn derivative_roots(c: &Cubic, degree: usize) -> (Option<f64>, Option<f64>) {
    match degree {
        3 => {
            let (a, b, cc) = (3.0 * c[3], 2.0 * c[2], c[1]);
            let disc = b * b - 4.0 * a * cc;
            if disc < 0.0 {
                return (None, None);
            }
            // Numerically stable quadratic formula.
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            if q == 0.0 {
                // b == 0 and disc == 0: a double root at 0.
                return (Some(0.0), None);
            }
            let (x1, x2) = (q / a, cc / q);
            (Some(x1.min(x2)), Some(x1.max(x2)))
        }
        2 => (Some(-c[1] / (2.0 * c[2])), None),
        _ => (None, None),
    }
}

/// An impulse's root is accepted once the volume error left is this fraction of the error it
/// corrects: far below what `f32` positions resolve (`6e-8`), and it spares the last Newton
/// steps to full `f64` precision, which cost more than the rest of the solve.
const IMPULSE_RESIDUAL: f64 = 1e-9;

/// Root of `c` in `[a, b]` where `c(a)` and `c(b)` have opposite signs, starting at `guess`:
/// Newton steps kept inside the bracket, bisection when Newton leaves it. The polynomial is
/// monotone on `[a, b]`. Stops early where `|c| <= residual` (0: only at `f64` precision).
fn bracketed_root(c: &Cubic, mut a: f64, mut b: f64, pa: f64, guess: f64, residual: f64) -> f64 {
    let rising = pa < 0.0;
    let mut x = if guess > a && guess < b {
        guess
    } else {
        0.5 * (a + b)
    };
    for _ in 0..200 {
        let px = eval(c, x);
        if px.abs() <= residual || px == 0.0 {
            return x;
        }
        if (px < 0.0) == rising {
            a = x;
        } else {
            b = x;
        }
        if b - a <= 4.0 * f64::EPSILON * b.abs().max(f64::MIN_POSITIVE) {
            break;
        }
        let dx = eval_derivative(c, x);
        let newton = if dx != 0.0 { x - px / dx } else { f64::NAN };
        if newton > a && newton < b {
            // Newton usually closes in from one side, so the bracket alone would not shrink:
            // stop once its step is at the limit of f64 precision.
            let converged = (newton - x).abs() <= 4.0 * f64::EPSILON * x.abs();
            x = newton;
            if converged {
                break;
            }
        } else {
            x = 0.5 * (a + b);
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers, so that a failure can be reproduced.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64) / ((1u64 << 53) as f64)
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next()
        }
        /// A cubic with coefficients uniform in [-1, 1].
        fn cubic(&mut self) -> Cubic {
            [0; 4].map(|_| self.range(-1.0, 1.0))
        }
    }

    fn from_roots(k: f64, r: [f64; 3]) -> Cubic {
        // k (s - r0)(s - r1)(s - r2)
        let [a, b, c] = r;
        [
            -k * a * b * c,
            k * (a * b + b * c + a * c),
            -k * (a + b + c),
            k,
        ]
    }

    /// The first sign change found by dense sampling, refined by bisection.
    fn sampled_first_crossing(c: &Cubic, hi: f64, samples: usize) -> Option<f64> {
        let mut prev = eval(c, 0.0);
        let mut prev_s = 0.0;
        for k in 1..=samples {
            let s = hi * k as f64 / samples as f64;
            let p = eval(c, s);
            if prev != 0.0 && p * prev < 0.0 || (prev_s > 0.0 && prev == 0.0) {
                if prev == 0.0 {
                    return Some(prev_s);
                }
                let (mut a, mut b) = (prev_s, s);
                for _ in 0..200 {
                    let m = 0.5 * (a + b);
                    if eval(c, m) * prev > 0.0 {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                return Some(0.5 * (a + b));
            }
            prev = p;
            prev_s = s;
        }
        None
    }

    #[test]
    fn known_roots_are_found() {
        let c = from_roots(2.0, [-1.0, 0.5, 3.0]);
        let r = smallest_positive_root(&c, f64::INFINITY).unwrap();
        assert!((r - 0.5).abs() < 1e-12, "{r}");
        let c = from_roots(-0.1, [4.0, 2.0, 7.0]);
        let r = smallest_positive_root(&c, f64::INFINITY).unwrap();
        assert!((r - 2.0).abs() < 1e-12, "{r}");
        // Bounded search misses roots above the bound.
        assert_eq!(smallest_positive_root(&c, 1.5), None);
    }

    #[test]
    fn random_cubics_match_dense_sampling() {
        let mut rng = Lcg(7);
        let mut checked = 0;
        for _ in 0..4000 {
            let c = rng.cubic();
            let hi = 10.0;
            let expected = sampled_first_crossing(&c, hi, 20_000);
            let got = first_crossing(&c, hi);
            match (expected, got) {
                (Some(e), Some(g)) => {
                    assert!((e - g).abs() < 1e-6, "{c:?}: sampled {e}, found {g}");
                    checked += 1;
                }
                (None, None) => {}
                (e, g) => {
                    // Sampling can only miss a crossing pair closer than its spacing.
                    let g = g.expect("the finder missed a crossing that sampling saw");
                    assert!(e.is_none());
                    let next = first_crossing(&[-c[0], -c[1], -c[2], -c[3]], hi);
                    assert!(next.is_some() || eval(&c, g).abs() < 1e-9, "{c:?}: {g}");
                }
            }
        }
        assert!(
            checked > 1000,
            "too few random cubics had a root: {checked}"
        );
    }

    #[test]
    fn cubics_clear_of_zero_do_not_cross_it() {
        let mut rng = Lcg(13);
        let (mut cleared, mut crossing) = (0, 0);
        for _ in 0..20_000 {
            let mut c = rng.cubic();
            c[0] = c[0].abs();
            let hi = rng.range(0.01, 2.0);
            let crosses =
                first_crossing(&c, hi).is_some() || sampled_first_crossing(&c, hi, 2_000).is_some();
            crossing += crosses as u32;
            if clear_of_zero(&c, hi) {
                cleared += 1;
                assert!(!crosses, "{c:?} on [0, {hi}] was cleared but crosses zero");
            }
        }
        // Both kinds were seen, and the test clears a good share of the rest.
        assert!(crossing > 1000, "{crossing} crossings");
        assert!(cleared > 4000, "{cleared} cleared");
    }

    #[test]
    fn random_cubics_with_planted_roots() {
        let mut rng = Lcg(11);
        for _ in 0..4000 {
            let roots = [
                rng.range(-5.0, 5.0),
                rng.range(-5.0, 5.0),
                rng.range(-5.0, 5.0),
            ];
            let k = rng.range(0.01, 100.0) * if rng.next() < 0.5 { -1.0 } else { 1.0 };
            let c = from_roots(k, roots);
            let expected = roots
                .iter()
                .copied()
                .filter(|&r| r > 1e-9)
                .fold(f64::INFINITY, f64::min);
            let got = smallest_positive_root(&c, f64::INFINITY);
            if expected.is_finite() {
                let g = got.unwrap_or_else(|| panic!("missed {expected} of {roots:?}"));
                assert!(
                    (g - expected).abs() < 1e-6 * (1.0 + expected),
                    "{roots:?}: {g}"
                );
            } else {
                assert!(got.is_none(), "{roots:?}: {got:?}");
            }
        }
    }

    #[test]
    fn degenerate_polynomials() {
        // Linear, quadratic, constant, zero, huge scale differences.
        assert_eq!(
            smallest_positive_root(&[-2.0, 4.0, 0.0, 0.0], f64::INFINITY),
            Some(0.5)
        );
        let r = smallest_positive_root(&[-1.0, 0.0, 1.0, 0.0], f64::INFINITY).unwrap();
        assert!((r - 1.0).abs() < 1e-12);
        assert_eq!(
            smallest_positive_root(&[1.0, 0.0, 0.0, 0.0], f64::INFINITY),
            None
        );
        assert_eq!(smallest_positive_root(&[0.0; 4], f64::INFINITY), None);
        assert_eq!(
            smallest_positive_root(&[1.0, 1.0, 1.0, 1.0], f64::INFINITY),
            None
        );
        let r = smallest_positive_root(&[-1e-30, 1e-30, 0.0, 1e-50], f64::INFINITY).unwrap();
        assert!((r - 1.0).abs() < 1e-9, "{r}");
        // Nearly a quadratic: a tiny cubic term must not hide the small root.
        let r = smallest_positive_root(&[-1.0, 0.0, 1.0, 1e-14], f64::INFINITY).unwrap();
        assert!((r - 1.0).abs() < 1e-9, "{r}");
        // Non-finite input is refused, not looped on.
        assert_eq!(
            smallest_positive_root(&[f64::NAN, 1.0, 0.0, 0.0], 1.0),
            None
        );
        assert_eq!(
            smallest_positive_root(&[-1.0, f64::INFINITY, 0.0, 0.0], 1.0),
            None
        );
    }

    #[test]
    fn double_roots_are_found_as_roots_but_not_as_crossings() {
        // (s - 1)^2 (s + 2): touches zero at 1.
        let c = from_roots(1.0, [1.0, 1.0, -2.0]);
        let r = smallest_positive_root(&c, f64::INFINITY).unwrap();
        assert!((r - 1.0).abs() < 1e-6, "{r}");
        assert_eq!(first_crossing(&c, 10.0), None);
        // A triple root crosses.
        let c = from_roots(1.0, [1.0, 1.0, 1.0]);
        let r = first_crossing(&c, 10.0).unwrap();
        assert!((r - 1.0).abs() < 1e-4, "{r}");
    }

    #[test]
    fn monotone_root_refuses_roots_past_a_turn() {
        // Moves towards zero and reaches it: the root.
        let r = monotone_root(&[-1.0, 2.0, 0.0, 0.0]).unwrap();
        assert!((r - 0.5).abs() < 1e-12);
        // Moves away from zero first: its positive root lies past a minimum.
        let c = from_roots(-1.0, [-1.0, -0.5, 3.0]);
        assert!(c[0] > 0.0 && c[1] > 0.0);
        assert!(smallest_positive_root(&c, f64::INFINITY).is_some());
        assert_eq!(monotone_root(&c), None);
        // Moves towards zero but turns back before reaching it.
        let c = [-1.0, 1.0, -1.0, 0.2];
        assert!(smallest_positive_root(&c, f64::INFINITY).is_some());
        assert_eq!(monotone_root(&c), None);
        // Agrees with the smallest positive root whenever it answers.
        let mut rng = Lcg(5);
        let mut answered = 0;
        for _ in 0..4000 {
            let c = rng.cubic();
            if let Some(r) = monotone_root(&c) {
                let s = smallest_positive_root(&c, f64::INFINITY).unwrap();
                assert!((r - s).abs() < 1e-9 * (1.0 + s), "{c:?}: {r} vs {s}");
                answered += 1;
            }
        }
        assert!(answered > 500);
    }

    #[test]
    fn the_nearly_linear_shortcut_finds_the_same_root() {
        // Volumes of impulses: nearly linear, sometimes not quite; the shortcut must answer as
        // the full search does, and must answer most of them itself.
        let mut rng = Lcg(11);
        let mut shortcut = 0;
        for k in 0..4000 {
            let curve = [0.01, 0.3, 3.0, 30.0][k % 4];
            let c = [
                rng.next() - 0.5,
                rng.next() * 4.0 - 2.0,
                (rng.next() - 0.5) * curve,
                (rng.next() - 0.5) * curve,
            ];
            let (fast, full) = (monotone_root(&c), monotone_root_general(&c));
            match (fast, full) {
                // Both stop once the error left is `IMPULSE_RESIDUAL` of the start.
                (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-8 * b, "{c:?}: {a} vs {b}"),
                (a, b) => assert_eq!(a, b, "{c:?}"),
            }
            let s0 = -c[0] / c[1];
            shortcut += (s0 > 0.0
                && 2.0 * s0 * (2.0 * c[2].abs() + 6.0 * c[3].abs() * s0) < c[1].abs())
                as usize;
        }
        assert!(shortcut > 1000, "{shortcut}");
    }

    #[test]
    fn crossing_from_zero() {
        // Starts at zero and decreases: crosses at once.
        assert_eq!(first_crossing(&[0.0, -1.0, 0.0, 0.0], 1.0), Some(0.0));
        // Starts at zero, rises, comes back down at s = 2.
        let r = first_crossing(&[0.0, 2.0, -1.0, 0.0], 10.0).unwrap();
        assert!((r - 2.0).abs() < 1e-12, "{r}");
        // Rises and stays up within the bound.
        assert_eq!(first_crossing(&[0.0, 2.0, -1.0, 0.0], 1.5), None);
    }
}
