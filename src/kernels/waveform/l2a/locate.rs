//! Signal start/end (toploc, botloc) and modes on the smoothed waveform.
//!
//! Crossings are interpolated linearly between samples and then put on the sub-bin grid the way
//! NASA's stored values fall (measured, docs/l2a.md): toploc is the first grid position at or after
//! the crossing, botloc the last grid position at or before it, modes the nearest grid position.

use super::Mode;

/// First position from the top where `smoothed` rises above `threshold`, on the 1/`grid` grid.
pub(super) fn signal_start(smoothed: &[f64], threshold: f64, grid: f64) -> Option<f64> {
    let i = smoothed.iter().position(|&v| v > threshold)?;
    if i == 0 {
        return Some(0.0);
    }
    let (a, b) = (smoothed[i - 1], smoothed[i]);
    let crossing = (i - 1) as f64 + (threshold - a) / (b - a);
    Some((crossing * grid).ceil() / grid)
}

/// Last position from the bottom where `smoothed` is above `threshold`, on the 1/`grid` grid.
pub(super) fn signal_end(smoothed: &[f64], threshold: f64, grid: f64) -> Option<f64> {
    let i = smoothed.iter().rposition(|&v| v > threshold)?;
    if i + 1 == smoothed.len() {
        return Some(i as f64);
    }
    let (a, b) = (smoothed[i], smoothed[i + 1]);
    let crossing = i as f64 + (a - threshold) / (a - b);
    Some((crossing * grid).floor() / grid)
}

/// Local maxima of `smoothed` above `threshold` with positions in `[top, bottom]`, top to bottom,
/// written to `out` (cleared first).
///
/// A maximum is a + → − sign change of the forward difference; its position is the zero crossing
/// of the difference (differences sit at half-sample positions), rounded to the grid.
pub(super) fn find_modes(smoothed: &[f64], top: f64, bottom: f64, threshold: f64, grid: f64, out: &mut Vec<Mode>) {
    out.clear();
    let n = smoothed.len();
    if n < 3 {
        return;
    }
    let first = (top.floor() as usize).max(1);
    let last = (bottom.ceil() as usize).min(n - 2);
    for i in first..=last {
        let rise = smoothed[i] - smoothed[i - 1];
        let fall = smoothed[i + 1] - smoothed[i];
        if rise > 0.0 && fall <= 0.0 && smoothed[i] > threshold {
            let x = i as f64 - 0.5 + rise / (rise - fall);
            if (top..=bottom).contains(&x) {
                out.push(Mode { position: (x * grid).round() / grid, amplitude: smoothed[i] });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_and_end_are_put_on_the_outer_grid_positions() {
        let s = [0.0, 0.0, 1.0, 3.0, 5.0, 3.0, 1.0, 0.0];
        // Rises above 2 between 2 and 3 at 2.5, falls below 2 between 5 and 6 at 5.5.
        assert_eq!(signal_start(&s, 2.0, 4.0), Some(2.5));
        assert_eq!(signal_end(&s, 2.0, 4.0), Some(5.5));
        assert_eq!(signal_start(&s, 1.5, 4.0), Some(2.25));
        assert_eq!(signal_end(&s, 1.5, 4.0), Some(5.75));
        assert_eq!(signal_start(&s, 9.0, 4.0), None);
    }

    #[test]
    fn modes_are_local_maxima_above_the_threshold() {
        let s = [0.0, 1.0, 4.0, 1.0, 0.5, 2.0, 3.0, 2.0, 0.0, 0.4, 0.0];
        let mut m = Vec::new();
        find_modes(&s, 0.0, 10.0, 0.5, 4.0, &mut m);
        let pos: Vec<f64> = m.iter().map(|m| m.position).collect();
        assert_eq!(pos, vec![2.0, 6.0]);
        assert_eq!(m[0].amplitude, 4.0);
    }
}
