//! The waveform-level gap: real and simulated waveforms, each normalised to unit energy, on a
//! grid of heights above the ALS ground, and the misfit of their means as a χ².
//!
//! RH percentiles are a few noisy summaries of a waveform; several effects that reshape the
//! waveform move them alike (docs/diagnosis.md). The mean normalised waveform keeps the shape —
//! where energy is missing or extra, and how wide the ground return is — averaged over shots, so
//! the noise of single waveforms cancels. It is kept per slope group, because a wider footprint
//! broadens the ground return only on slopes while a wider pulse broadens it everywhere.
//!
//! Per shot, the difference d = real − simulated is stored; d's mean and its between-shot spread
//! per height bin give χ² = Σ_bins mean(d)² / var(mean(d)), additive over shots through
//! [`ProfileSums`] like the RH gap, so that tracks and bootstrap resamples combine by addition.

use super::case::{ShotCase, Site};
use super::chain::{pulsed_parts, same_before_pulse, simulated_wave, Model};
use crate::scenario::effects::{Effect, WaveParts};
use crate::waveform::noise_twin::GEDI_BIN_M;

/// Height grid: bins of this size (m) from [`PROFILE_MIN_M`].
pub const PROFILE_BIN_M: f64 = 0.5;
pub const PROFILE_MIN_M: f64 = -10.0;
pub const PROFILE_BINS: usize = 140;
/// Slope groups: < 10° (flat) and the rest (sloped or unknown).
pub const PROFILE_GROUPS: usize = 2;

/// Add `v` at height `h` to `acc`, shared between the two nearest bin centres (linear weights):
/// 1 ns samples (0.15 m) do not tile 0.5 m bins, and nearest-bin counting would show a saw-tooth.
pub fn add_at_height(acc: &mut [f64], h: f64, v: f64) {
    add_at(acc, grid_place(h), v);
}

/// Where height `h` lands on the height grid: the lower bin centre's index (as a float, may lie
/// outside the grid) and the upper one's weight.
fn grid_place(h: f64) -> (f64, f64) {
    let p = (h - PROFILE_MIN_M) / PROFILE_BIN_M - 0.5;
    let i = floor(p);
    (i, p - i)
}

/// `p.floor()` without the libm call it is on x86-64's baseline (no rounding instruction): the
/// truncation, one lower for a negative non-integer; exact (|p| < 2⁵² is truncated exactly).
fn floor(p: f64) -> f64 {
    if p.abs() < 4.0e15 {
        let t = p as i64 as f64;
        if t > p {
            t - 1.0
        } else {
            t
        }
    } else {
        p.floor()
    }
}

/// [`add_at_height`] at a place [`grid_place`] gave.
fn add_at(acc: &mut [f64], (i, w): (f64, f64), v: f64) {
    for (j, f) in [(i, 1.0 - w), (i + 1.0, w)] {
        if j >= 0.0 && (j as usize) < acc.len() {
            acc[j as usize] += v * f;
        }
    }
}

/// Bin centres (m above the ALS ground).
pub fn heights() -> Vec<f64> {
    (0..PROFILE_BINS).map(|i| PROFILE_MIN_M + (i as f64 + 0.5) * PROFILE_BIN_M).collect()
}

/// The real waveform of `case` (noise mean removed) on the height grid above the ALS ground of
/// `site`, normalised to unit sum, its elevations corrected by `vertical_offset_m` (GEDI − ALS).
/// `None` without energy.
pub fn real_profile(case: &ShotCase, site: &Site, vertical_offset_m: f64) -> Option<Vec<f64>> {
    let g = site.als_ground + vertical_offset_m;
    let mut r = vec![0.0; PROFILE_BINS];
    for (s, &v) in case.real.wave.iter().enumerate() {
        add_at_height(&mut r, case.real.bin0 - s as f64 * GEDI_BIN_M - g, f64::from(v));
    }
    normalised(r)
}

/// The model's noise-free simulated waveform of `case` on the height grid, normalised.
pub fn simulated_profile(case: &ShotCase, model: &Model) -> Option<Vec<f64>> {
    let site = model.site(case);
    profile_of(&simulated_wave(case, model), site.z0, case.sim.dz, site.als_ground)
}

/// `wave` (bins of `dz` from `z0`) on the height grid above `ground`, normalised.
fn profile_of(wave: &[f64], z0: f64, dz: f64, ground: f64) -> Option<Vec<f64>> {
    let mut m = vec![0.0; PROFILE_BINS];
    // Zero bins add nothing.
    for (k, &v) in wave.iter().enumerate().filter(|(_, &v)| v != 0.0) {
        add_at_height(&mut m, z0 - k as f64 * dz - ground, v);
    }
    normalised(m)
}

fn normalised(mut v: Vec<f64>) -> Option<Vec<f64>> {
    normalise(&mut v).then_some(v)
}

/// Scale `v` to unit sum; false (unchanged) without a positive finite sum.
fn normalise(v: &mut [f64]) -> bool {
    let s: f64 = v.iter().sum();
    if !(s > 0.0 && s.is_finite()) {
        return false;
    }
    v.iter_mut().for_each(|x| *x /= s);
    true
}

/// Slope group of a case.
pub fn group(case: &ShotCase) -> usize {
    usize::from(case.real.strata.slope_class != crate::study::classes::slope_class(Some(0.0)))
}

/// One shot's profile difference (real − simulated) and its slope group.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotProfile {
    pub group: usize,
    pub diff: Vec<f32>,
}

/// The profile difference of `case` under `model`.
pub fn shot_profile(case: &ShotCase, model: &Model) -> Option<ShotProfile> {
    let r = real_profile(case, model.site(case), model.vertical_offset_m())?;
    let m = simulated_profile(case, model)?;
    Some(difference(group(case), &r, &m))
}

fn difference(group: usize, real: &[f64], simulated: &[f64]) -> ShotProfile {
    ShotProfile { group, diff: real.iter().zip(simulated).map(|(a, b)| (a - b) as f32).collect() }
}

/// Σd and Σd² per group and bin, and the shot counts.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileSums {
    pub n: [f64; PROFILE_GROUPS],
    pub sd: Vec<f64>,
    pub sdd: Vec<f64>,
}

impl Default for ProfileSums {
    fn default() -> Self {
        ProfileSums {
            n: [0.0; PROFILE_GROUPS],
            sd: vec![0.0; PROFILE_GROUPS * PROFILE_BINS],
            sdd: vec![0.0; PROFILE_GROUPS * PROFILE_BINS],
        }
    }
}

impl ProfileSums {
    pub fn add(&mut self, p: &ShotProfile) {
        if p.group >= PROFILE_GROUPS || p.diff.len() != PROFILE_BINS {
            return;
        }
        self.n[p.group] += 1.0;
        let o = p.group * PROFILE_BINS;
        for (i, &d) in p.diff.iter().enumerate() {
            let d = f64::from(d);
            self.sd[o + i] += d;
            self.sdd[o + i] += d * d;
        }
    }

    pub fn merge(&mut self, o: &ProfileSums) {
        for g in 0..PROFILE_GROUPS {
            self.n[g] += o.n[g];
        }
        self.sd.iter_mut().zip(&o.sd).for_each(|(a, b)| *a += b);
        self.sdd.iter_mut().zip(&o.sdd).for_each(|(a, b)| *a += b);
    }

    /// χ² of the mean difference, Σ mean² / (var / n) over the bins of groups with ≥ 3 shots,
    /// against its own between-shot variance ([`ProfileSums::chi2_against`]).
    pub fn chi2(&self) -> f64 {
        self.chi2_against(self)
    }

    /// χ² of this set's mean difference against the between-shot variance of `reference` (the
    /// same shots under a reference model): Σ mean² / (var_ref / n) over the bins of groups with
    /// ≥ 3 shots; bins whose reference difference never varies (no energy on either side) count
    /// nothing. Its expectation is about the number of bins used when the model is right.
    ///
    /// Hypotheses are compared against one fixed variance: against its own, a model that fits
    /// every shot worse widens the scatter of d and so lowers its χ² (docs/diagnosis.md, "The
    /// waveform misfit is weighed by one variance").
    pub fn chi2_against(&self, reference: &ProfileSums) -> f64 {
        let mut chi2 = 0.0;
        for g in 0..PROFILE_GROUPS {
            let (n, nr) = (self.n[g], reference.n[g]);
            if n < 3.0 || nr < 3.0 {
                continue;
            }
            for i in g * PROFILE_BINS..(g + 1) * PROFILE_BINS {
                let mean = self.sd[i] / n;
                let mean_ref = reference.sd[i] / nr;
                let var = (reference.sdd[i] / nr - mean_ref * mean_ref).max(0.0) * nr / (nr - 1.0);
                if var > 1e-18 {
                    chi2 += mean * mean / (var / n);
                }
            }
        }
        chi2
    }
}

impl<'a> FromIterator<&'a ShotProfile> for ProfileSums {
    fn from_iter<I: IntoIterator<Item = &'a ShotProfile>>(profiles: I) -> ProfileSums {
        let mut s = ProfileSums::default();
        profiles.into_iter().for_each(|p| s.add(p));
        s
    }
}

/// The profile sums of `model` on `cases` (in parallel).
pub fn sums(cases: &[&ShotCase], model: &Model) -> ProfileSums {
    use rayon::prelude::*;
    let profiles: Vec<ShotProfile> = cases.par_iter().filter_map(|c| shot_profile(c, model)).collect();
    profiles.iter().collect()
}

/// The shots of a fit prepared once for the effects that act after the pulse (a ground/vegetation
/// ratio, a canopy change, an occlusion): each shot's real profile and its simulated parts
/// convolved with the pulse, the base model's own after-pulse effects applied. A fit's every
/// trial value then costs a composition, not a simulation; [`AfterPulse::sums`] gives the same
/// numbers as [`sums`] of the base model with the effect.
pub struct AfterPulse<'a> {
    cases: &'a [&'a ShotCase],
    base: Model,
    /// Prepared on the first effect that acts after the pulse.
    shots: std::cell::OnceCell<Vec<Option<Prepared>>>,
}

/// A shot prepared for the effects that act after the pulse.
struct Prepared {
    /// Its real profile.
    real: Vec<f64>,
    /// Its pulsed parts, the base model's after-pulse effects applied.
    parts: WaveParts,
    group: usize,
    /// The bins of the parts that land on the height grid, and where: the index of the lower bin
    /// centre plus one (in a grid padded by one bin on each side), its weight and the upper one's
    /// ([`grid_place`]).
    bins: std::ops::Range<usize>,
    places: Vec<(usize, f64, f64)>,
}

impl<'a> AfterPulse<'a> {
    pub fn new(cases: &'a [&'a ShotCase], base: &Model) -> AfterPulse<'a> {
        AfterPulse { cases, base: base.clone(), shots: std::cell::OnceCell::new() }
    }

    fn prepare(&self) -> Vec<Option<Prepared>> {
        use rayon::prelude::*;
        let (base, vo) = (&self.base, self.base.vertical_offset_m());
        self.cases
            .par_iter()
            .map(|c| {
                let site = base.site(c);
                let real = real_profile(c, site, vo)?;
                let mut parts = pulsed_parts(c.sim.dz, site, base, c.real.pulse.as_deref());
                base.apply_after_pulse(&mut parts);
                // As profile_of places bin k of the composed waveform: the lower centre i and
                // i + 1 land on the grid for −1 ≤ i < PROFILE_BINS.
                let place = |k: usize| grid_place(parts.z0 - k as f64 * parts.dz - parts.ground_z);
                let on_grid = |k: &usize| (-1.0..PROFILE_BINS as f64).contains(&place(*k).0);
                let first = (0..parts.canopy.len()).find(on_grid).unwrap_or(0);
                let end = (first..parts.canopy.len()).rev().find(on_grid).map_or(first, |k| k + 1);
                let places = (first..end)
                    .map(|k| {
                        let (i, w) = place(k);
                        ((i + 1.0) as usize, 1.0 - w, w)
                    })
                    .collect();
                Some(Prepared { real, parts, group: group(c), bins: first..end, places })
            })
            .collect()
    }

    /// The profile sums of the base model with `e` ([`sums`] when `e` acts before the pulse).
    pub fn sums(&self, e: &Effect) -> ProfileSums {
        use rayon::prelude::*;
        let model = self.base.with(e.clone());
        if !same_before_pulse(&model, &self.base) {
            return sums(self.cases, &model);
        }
        // `profile_of(composed(parts with e applied))`, bin by bin without the copies: the canopy
        // band of e scaled, ρ·ground added, clipped at 0, placed on the grid where it was prepared.
        let (band, rho) = (e.canopy_band(), model.weighting().1);
        let bands = band.as_slice();
        let profiles: Vec<ShotProfile> = self
            .shots
            .get_or_init(|| self.prepare())
            .par_iter()
            .map_init(
                || vec![0.0; PROFILE_BINS + 2],
                |padded, s| {
                    let p = s.as_ref()?;
                    padded.iter_mut().for_each(|v| *v = 0.0);
                    let parts = &p.parts;
                    let (canopy, ground) = (&parts.canopy[p.bins.clone()], &parts.ground[p.bins.clone()]);
                    for (j, ((&c, &g), &(i, a, w))) in canopy.iter().zip(ground).zip(&p.places).enumerate() {
                        let c = if bands.is_empty() {
                            c
                        } else {
                            Effect::scaled_in_bands(c, parts.height(p.bins.start + j), bands)
                        };
                        let v = (c + rho * g).max(0.0);
                        if v != 0.0 {
                            padded[i] += v * a;
                            padded[i + 1] += v * w;
                        }
                    }
                    let m = &mut padded[1..=PROFILE_BINS];
                    normalise(m).then(|| difference(p.group, &p.real, m))
                },
            )
            .flatten()
            .collect();
        profiles.iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_binning_keeps_the_sum_and_the_mean_height() {
        let mut acc = vec![0.0; PROFILE_BINS];
        add_at_height(&mut acc, 3.3, 2.0);
        assert!((acc.iter().sum::<f64>() - 2.0).abs() < 1e-12);
        let h = heights();
        let mean: f64 = acc.iter().zip(&h).map(|(v, h)| v * h).sum::<f64>() / 2.0;
        assert!((mean - 3.3).abs() < 1e-9, "{mean}");
    }

    #[test]
    fn chi2_is_zero_for_equal_profiles_and_grows_with_a_shift() {
        let mut same = ProfileSums::default();
        let mut off = ProfileSums::default();
        for i in 0..20 {
            let noise = |k: usize| ((i * 7 + k * 13) % 11) as f32 * 1e-4 - 5e-4;
            same.add(&ShotProfile { group: 0, diff: (0..PROFILE_BINS).map(|k| noise(k) * 0.0).collect() });
            off.add(&ShotProfile {
                group: 0,
                diff: (0..PROFILE_BINS).map(|k| noise(k) + if k == 20 { 0.01 } else { 0.0 }).collect(),
            });
        }
        assert_eq!(same.chi2(), 0.0);
        let mut merged = ProfileSums::default();
        merged.merge(&off);
        assert_eq!(merged.chi2(), off.chi2());
        assert!(off.chi2() > 100.0, "{}", off.chi2());
    }

    #[test]
    fn scatter_does_not_lower_chi2_against_a_fixed_variance() {
        // The same mean misfit (0.01 at one bin), once with tight and once with wide scatter.
        let set = |spread: f32| {
            let mut s = ProfileSums::default();
            for i in 0..20 {
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                s.add(&ShotProfile {
                    group: 0,
                    diff: (0..PROFILE_BINS).map(|k| if k == 20 { 0.01 + sign * spread } else { 0.0 }).collect(),
                });
            }
            s
        };
        let (tight, wide) = (set(5e-4), set(5e-3));
        // Against its own variance the scattered model looks 100 times better…
        assert!(wide.chi2() < 0.02 * tight.chi2(), "{} vs {}", wide.chi2(), tight.chi2());
        // …against the reference's it is what it is: the same mean misfit.
        let (a, b) = (wide.chi2_against(&tight), tight.chi2());
        assert!((a - b).abs() < 1e-6 * b, "{a} vs {b}");
    }
}
