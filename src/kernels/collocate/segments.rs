//! Which shots share an offset (docs/contracts.md, "Collocate"): runs of consecutive covered shots cut
//! into segments of at most `--segment` shots, per beam, per granule (all beams, along track), or
//! one window of neighbours per shot.

/// The level at which offsets are solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Level {
    /// Each beam of a granule, cut into runs of consecutive covered shots.
    Beam,
    /// All beams of a granule share an offset per along-track run. (A *track* is one beam's ground
    /// track everywhere in gedisim; `track` is accepted on the command line for this level, as
    /// docs/contracts.md first named it.)
    Granule,
    /// One offset per shot, with its neighbours for support.
    Shot,
}

impl Level {
    /// Name in the `level` column and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Level::Beam => "beam",
            Level::Granule => "granule",
            Level::Shot => "shot",
        }
    }

    /// The level named `name` ([`name`](Self::name)).
    pub fn from_name(name: &str) -> Option<Level> {
        [Level::Beam, Level::Granule, Level::Shot].into_iter().find(|l| l.name() == name)
    }
}

/// Fewest shots (beam) or along-track steps (granule) of a segment: a shorter remainder joins the
/// previous segment of its run, a shorter run is reported and not solved.
pub const MIN_SEGMENT: usize = 20;

/// Neighbours on each side of a shot supporting its offset at the shot level (along its beam,
/// within its run): 2, so 5 waveforms per shot where the run allows.
pub const SHOT_NEIGHBOURS: usize = 2;

/// One shot of a beam or granule in along-track order, as the segmentation sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Along-track step (consecutive shots of a beam differ by 1; shots of different beams fired
    /// together share it).
    pub step: i64,
    /// The ALS covers the shot's footprint (an uncovered shot ends a run).
    pub covered: bool,
    /// The shot can be used (covered, with a usable waveform).
    pub usable: bool,
}

/// Shots that share one offset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentPlan {
    /// The shots whose waveforms are correlated (indices into the slots).
    pub support: Vec<usize>,
    /// The shots the offset applies to (= `support` except at the shot level).
    pub applies_to: Vec<usize>,
}

/// A run too short to be solved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShortRun {
    /// Its usable shots.
    pub shots: Vec<usize>,
}

/// Segments of `slots` (sorted by `step`, ties in any order) at `level`; `segment` is the
/// maximal length (shots at the beam level, steps at the granule level). A run is a maximal
/// sequence of covered shots at consecutive steps. Runs shorter than
/// min(`segment`, `min_segment`) (default [`MIN_SEGMENT`]) are returned apart (beam and track
/// levels).
pub fn plan(slots: &[Slot], level: Level, segment: usize, min_segment: usize) -> (Vec<SegmentPlan>, Vec<ShortRun>) {
    let segment = segment.max(1);
    let min_len = segment.min(min_segment).max(1);
    let mut plans = Vec::new();
    let mut short = Vec::new();
    for run in runs(slots) {
        match level {
            Level::Beam => {
                let usable: Vec<usize> = run.into_iter().filter(|&i| slots[i].usable).collect();
                cut(usable.len(), segment, min_len, &mut short, &usable, |range| {
                    let s = usable[range].to_vec();
                    plans.push(SegmentPlan { support: s.clone(), applies_to: s });
                });
            }
            Level::Granule => {
                // Cut by distinct steps; every usable shot of a step belongs to its segment.
                let mut steps: Vec<(i64, Vec<usize>)> = Vec::new();
                for i in run {
                    match steps.last_mut() {
                        Some((s, v)) if *s == slots[i].step => v.push(i),
                        _ => steps.push((slots[i].step, vec![i])),
                    }
                }
                let usable_of = |r: std::ops::Range<usize>| -> Vec<usize> {
                    steps[r].iter().flat_map(|(_, v)| v.iter().copied()).filter(|&i| slots[i].usable).collect()
                };
                let all = usable_of(0..steps.len());
                cut(steps.len(), segment, min_len, &mut short, &all, |range| {
                    let s = usable_of(range);
                    if !s.is_empty() {
                        plans.push(SegmentPlan { support: s.clone(), applies_to: s });
                    }
                });
            }
            Level::Shot => {
                let usable: Vec<usize> = run.into_iter().filter(|&i| slots[i].usable).collect();
                for (k, &i) in usable.iter().enumerate() {
                    let lo = k.saturating_sub(SHOT_NEIGHBOURS);
                    let hi = (k + SHOT_NEIGHBOURS + 1).min(usable.len());
                    plans.push(SegmentPlan { support: usable[lo..hi].to_vec(), applies_to: vec![i] });
                }
            }
        }
    }
    (plans, short)
}

/// Cuts `len` items into ranges of at most `segment`, a remainder under `min_len` joining the
/// previous range; a total under `min_len` is a short run.
fn cut(
    len: usize,
    segment: usize,
    min_len: usize,
    short: &mut Vec<ShortRun>,
    shots: &[usize],
    mut emit: impl FnMut(std::ops::Range<usize>),
) {
    if len == 0 {
        return;
    }
    if len < min_len {
        if !shots.is_empty() {
            short.push(ShortRun { shots: shots.to_vec() });
        }
        return;
    }
    let mut start = 0;
    while start < len {
        let mut end = (start + segment).min(len);
        if len - end < min_len {
            end = len;
        }
        emit(start..end);
        start = end;
    }
}

/// Maximal sequences of covered slots at consecutive steps (indices into `slots`): a step with
/// no covered slot ends a run (at the beam level, an uncovered shot; at the granule level, a step
/// where no beam is covered).
fn runs(slots: &[Slot]) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut last_step: Option<i64> = None;
    for (i, s) in slots.iter().enumerate().filter(|(_, s)| s.covered) {
        let continues = last_step.is_some_and(|p| s.step == p || s.step == p + 1);
        if !continues {
            out.push(Vec::new());
        }
        out.last_mut().expect("a run was started").push(i);
        last_step = Some(s.step);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn beam(covered: &[bool]) -> Vec<Slot> {
        covered.iter().enumerate().map(|(i, &c)| Slot { step: i as i64, covered: c, usable: c }).collect()
    }

    #[test]
    fn beam_runs_are_cut_with_the_remainder_joined() {
        // 95 covered, a gap, 12 covered.
        let mut c = vec![true; 95];
        c.push(false);
        c.extend(vec![true; 12]);
        let slots = beam(&c);
        let (plans, short) = plan(&slots, Level::Beam, 40, MIN_SEGMENT);
        let lens: Vec<usize> = plans.iter().map(|p| p.support.len()).collect();
        assert_eq!(lens, vec![40, 55]);
        assert_eq!(short.len(), 1);
        assert_eq!(short[0].shots, (96..108).collect::<Vec<_>>());
        // A run of 100 splits 40, 40, 20.
        let (plans, _) = plan(&beam(&[true; 100]), Level::Beam, 40, MIN_SEGMENT);
        assert_eq!(plans.iter().map(|p| p.support.len()).collect::<Vec<_>>(), vec![40, 40, 20]);
    }

    #[test]
    fn unusable_shots_inside_a_run_are_left_out_without_ending_it() {
        let mut slots = beam(&[true; 30]);
        slots[10].usable = false;
        let (plans, short) = plan(&slots, Level::Beam, 40, MIN_SEGMENT);
        assert!(short.is_empty());
        assert_eq!(plans.len(), 1);
        assert_eq!(plans[0].support.len(), 29);
        assert!(!plans[0].support.contains(&10));
    }

    #[test]
    fn track_segments_take_every_beam_of_their_steps() {
        // Two beams over steps 0..50; beam B uncovered for steps 20..25.
        let mut slots = Vec::new();
        for step in 0..50 {
            slots.push(Slot { step, covered: true, usable: true });
            let b = !(20..25).contains(&step);
            slots.push(Slot { step, covered: b, usable: b });
        }
        let (plans, short) = plan(&slots, Level::Granule, 40, MIN_SEGMENT);
        assert!(short.is_empty());
        assert_eq!(plans.len(), 1, "50 steps: 40 + a remainder of 10 joins");
        assert_eq!(plans[0].support.len(), 95);
        // A step where no beam is covered ends the run.
        for s in slots.iter_mut().filter(|s| s.step == 30) {
            s.covered = false;
        }
        let (plans, short) = plan(&slots, Level::Granule, 40, MIN_SEGMENT);
        assert_eq!(plans.len(), 1);
        assert_eq!(short.len(), 1, "the 19 steps after the gap are too short");
    }

    #[test]
    fn shot_level_windows_stay_in_the_run() {
        let (plans, short) = plan(&beam(&[true; 6]), Level::Shot, 40, MIN_SEGMENT);
        assert!(short.is_empty());
        assert_eq!(plans.len(), 6);
        assert_eq!(plans[0].support, vec![0, 1, 2]);
        assert_eq!(plans[3].support, vec![1, 2, 3, 4, 5]);
        assert_eq!(plans[3].applies_to, vec![3]);
    }
}
