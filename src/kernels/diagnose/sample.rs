//! Which shots the effects are ranked on (docs/diagnosis.md, "Shots ranked"). Where the gap lies
//! is measured on every shot; the configuration, the effects and the self-test — each shot
//! simulated at every site and width, every twin set ranked again — on the shots of whole tracks
//! drawn at random, up to [`RANKED_SHOTS`]. Whole tracks keep the split by track (folds, the
//! bootstrap) and every collocation segment whole.

use std::collections::{BTreeMap, BTreeSet};

use crate::scenario::rng::derive_seed;

/// Shots ranked by default (`--ranked-shots`): the tracks drawn until they hold this many.
pub const RANKED_SHOTS: usize = 1000;

/// The tracks whose shots are ranked, from the number of shots of each: every track when they hold
/// at most `max` shots (or `max` is 0), else tracks in an order fixed by a hash of their names —
/// the same dataset draws the same tracks — until the drawn ones hold at least `max` shots.
pub fn ranked_tracks<'a>(shots: impl IntoIterator<Item = &'a str>, max: usize) -> BTreeSet<String> {
    let mut per_track: BTreeMap<&str, usize> = BTreeMap::new();
    shots.into_iter().for_each(|t| *per_track.entry(t).or_default() += 1);
    let total: usize = per_track.values().sum();
    if max == 0 || total <= max {
        return per_track.into_keys().map(str::to_string).collect();
    }
    let mut order: Vec<(u64, &str, usize)> =
        per_track.into_iter().map(|(t, n)| (derive_seed(0x5A3B1E, &["ranked track", t]), t, n)).collect();
    order.sort_unstable();
    let mut out = BTreeSet::new();
    let mut n = 0;
    for (_, t, k) in order {
        if n >= max {
            break;
        }
        out.insert(t.to_string());
        n += k;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shots(tracks: usize, per: usize) -> Vec<String> {
        (0..tracks).flat_map(|t| std::iter::repeat_n(format!("g{t}/BEAM0101"), per)).collect()
    }

    #[test]
    fn every_track_when_they_hold_few_shots() {
        let s = shots(20, 10);
        assert_eq!(ranked_tracks(s.iter().map(String::as_str), 200).len(), 20);
        assert_eq!(ranked_tracks(s.iter().map(String::as_str), 0).len(), 20);
    }

    #[test]
    fn whole_tracks_up_to_the_limit_the_same_each_time() {
        let s = shots(100, 10);
        let a = ranked_tracks(s.iter().map(String::as_str), 250);
        assert_eq!(a.len(), 25, "whole tracks of 10 shots until 250");
        assert_eq!(a, ranked_tracks(s.iter().rev().map(String::as_str), 250), "independent of the shots' order");
        // Not simply the first tracks by name.
        let first: BTreeSet<String> = (0..25).map(|t| format!("g{t}/BEAM0101")).collect();
        assert_ne!(a, first);
    }
}
