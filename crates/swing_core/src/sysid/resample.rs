//! Linear resampling of flight columns onto the model's sample time: the one resampler of
//! identification (a flight logged at any rate is identified at `dt`).

/// Linear interpolation of `cols` (sampled at the strictly increasing `t`) onto
/// t0, t0 + dt, … ≤ t_end, time-major; also the sample count.
pub fn resample(t: &[f64], cols: &[&[f64]], dt: f64) -> (Vec<f64>, usize) {
    let span = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    let count = if t.len() < 2 {
        0
    } else {
        (span / dt + 1e-9).floor() as usize + 1
    };
    let mut out = Vec::with_capacity(count * cols.len());
    let mut j = 0;
    for k in 0..count {
        let tk = t[0] + dt * k as f64;
        while j + 2 < t.len() && t[j + 1] < tk {
            j += 1;
        }
        let (t0, t1) = (t[j], t[j + 1]);
        let w = ((tk - t0) / (t1 - t0)).clamp(0.0, 1.0);
        for c in cols {
            out.push(c[j] + w * (c[j + 1] - c[j]));
        }
    }
    (out, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resample_is_exact_on_lines() {
        let t: Vec<f64> = (0..50)
            .map(|k| 0.01 * k as f64 + 0.003 * (k % 3) as f64)
            .collect();
        let c: Vec<f64> = t.iter().map(|t| 2.0 * t - 1.0).collect();
        let (x, n) = resample(&t, &[&c], 0.03);
        assert_eq!(n, ((t[49] - t[0]) / 0.03).floor() as usize + 1);
        for (k, v) in x.iter().enumerate() {
            let tk = t[0] + 0.03 * k as f64;
            assert!((v - (2.0 * tk - 1.0)).abs() < 1e-12);
        }
    }
}
