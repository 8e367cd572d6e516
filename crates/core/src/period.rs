//! Periodic solids: with a period P (per axis, in finest voxels) the whole
//! solid repeats, voxel(p) = voxel(p + P·eᵢ) exactly, at every level of
//! detail, so one block of P voxels tiles space without a seam (what a
//! shader sampling a 3D texture with repeat wrapping needs).
//!
//! Synthesis is a function of position only through a few things, and each
//! is made periodic with period P_k = P / 2^k at level k:
//!
//! - every random choice hashes a cell index, taken modulo the number of
//!   cells per period (`Intervals`): the slab's pieces, the jitter's
//!   Gaussian cells;
//! - what a piece of the slab or the jitter computes from a position, it
//!   computes from the position moved into the period of the piece's own
//!   copy, so that p and p + P_k compute the same numbers;
//! - the field's frames are read at the point wrapped into one period;
//! - the dual grid's cells are laid out per period: ⌈P_k / M⌉ cells of at
//!   most M voxels, so that their walls repeat with the period;
//! - the subpass classes (modulo the block side s, or parity) and the
//!   upsampling's child offsets (modulo 2) repeat by themselves when P_k is
//!   a multiple of s and of 2;
//! - a tile and its copies one period away share one cache key, so a
//!   request anywhere reuses what was synthesized for any copy.
//!
//! Hence P must be a multiple of 2^L (L the coarsest level, so that P_k is
//! whole at every level) times the tile side 4 (tiles line up with the
//! period at every level; this also makes P_k even) and, with block side 3,
//! times 3 ([`multiple`]).
//!
//! Cost: none per voxel. The cells of the slab, the jitter and the dual
//! grid are resized by less than a factor 2 to fit a whole number into a
//! period; the work estimates of periodic textures take the bound without
//! cell walls (the cells are no longer uniform), so admission control sees
//! them somewhat costlier than they are. A request larger than a period
//! synthesizes one period and copies it.

use crate::error::{Error, Result};
use crate::params::SynthParams;
use serde::Deserialize;

/// Largest period per axis, in finest voxels: a slice of one whole period
/// still fits a slice request ([`crate::MAX_SLICE_SIDE`]).
pub const MAX_PERIOD: u32 = 4096;

/// Side of the cached tiles, which a period lines up with at every level.
const TILE: i64 = crate::synth::TILE;

/// What every side of a period must be a multiple of, for candidates of
/// `levels` pyramid levels under `params`: the coarsest level's spacing
/// 2^(levels − 1) times the tile side (times 3 with subpass block side 3).
pub fn multiple(levels: usize, params: &SynthParams) -> u32 {
    let coarsest = 1u32 << levels.saturating_sub(1);
    let blocks_of_three = params.subpass_side == 3
        && (params.parity_levels as usize) < levels
        && (params.passes > 0 || params.finest_passes > 0);
    coarsest * TILE as u32 * if blocks_of_three { 3 } else { 1 }
}

/// Checks a period against candidates of `levels` levels (its range is
/// checked with the other parameters, [`SynthParams::validate`]).
pub fn check(period: [u32; 3], levels: usize, params: &SynthParams) -> Result<()> {
    let m = multiple(levels, params);
    if let Some(bad) = period.iter().find(|&&side| side % m != 0) {
        return Err(Error::InvalidRequest(format!(
            "period {bad} is not a multiple of {m} (the coarsest level's spacing {} × {}): \
             every level must hold whole tiles of one period",
            1u32 << levels.saturating_sub(1),
            m >> levels.saturating_sub(1),
        )));
    }
    Ok(())
}

/// A texture's period at every level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Period {
    finest: [i64; 3],
}

impl Period {
    /// The period of `params`, if it has one.
    pub(crate) fn of(params: &SynthParams) -> Option<Period> {
        params.period.map(|p| Period {
            finest: p.map(i64::from),
        })
    }

    /// P_k: the period in voxels of level `k`.
    pub(crate) fn at(&self, k: usize) -> [i64; 3] {
        self.finest.map(|p| p >> k)
    }

    /// The period in finest voxels, as the field's points measure it.
    pub(crate) fn finest(&self) -> [f64; 3] {
        self.finest.map(|p| p as f64)
    }

    /// Tile `cell` of level `k` moved into the period at the origin.
    pub(crate) fn wrap_tile(&self, k: usize, cell: [i64; 3]) -> [i64; 3] {
        let per = self.at(k);
        [0, 1, 2].map(|a| cell[a].rem_euclid(per[a] / TILE))
    }

    /// Cells of the dual grid at level `k`: at most `side` voxels, a whole
    /// number per period.
    pub(crate) fn cells(&self, k: usize, side: i64) -> [Intervals; 3] {
        self.at(k).map(|per| Intervals::at_most(per, side))
    }
}

/// Intervals that tile the integer line, numbered from the one that starts
/// at 0: all of one side, or a whole number of them per period (each of
/// the period divided evenly, rounded down at its ends), repeating.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Intervals {
    /// `side` voxels each.
    Uniform(i64),
    /// `count` per `period` voxels.
    Periodic {
        /// The period.
        period: i64,
        /// Intervals per period.
        count: i64,
    },
}

impl Intervals {
    /// Intervals as near `side` as a whole number per `period` allows
    /// (none fewer than one per period).
    pub(crate) fn nearest(period: Option<i64>, side: i64) -> Intervals {
        match period {
            None => Intervals::Uniform(side),
            Some(period) => Intervals::Periodic {
                period,
                count: ((period + side / 2) / side).max(1),
            },
        }
    }

    /// The fewest intervals per `period` none of which is longer than
    /// `side`.
    pub(crate) fn at_most(period: i64, side: i64) -> Intervals {
        Intervals::Periodic {
            period,
            count: (period + side - 1) / side,
        }
    }

    /// First voxel of interval `i`.
    #[inline]
    pub(crate) fn start(&self, i: i64) -> i64 {
        match *self {
            Intervals::Uniform(side) => i * side,
            Intervals::Periodic { period, count } => {
                i.div_euclid(count) * period + i.rem_euclid(count) * period / count
            }
        }
    }

    /// Number of voxels of interval `i`.
    #[inline]
    pub(crate) fn size(&self, i: i64) -> i64 {
        match *self {
            Intervals::Uniform(side) => side,
            Intervals::Periodic { .. } => self.start(i + 1) - self.start(i),
        }
    }

    /// The interval holding voxel `x`.
    #[inline]
    pub(crate) fn index_of(&self, x: i64) -> i64 {
        match *self {
            Intervals::Uniform(side) => x.div_euclid(side),
            Intervals::Periodic { period, count } => {
                // The last j with ⌊j·period / count⌋ ≤ r.
                let r = x.rem_euclid(period);
                x.div_euclid(period) * count + ((r + 1) * count - 1) / period
            }
        }
    }

    /// What a hash sees of interval `i`: `i` itself, or its number within
    /// its period.
    #[inline]
    pub(crate) fn label(&self, i: i64) -> i64 {
        match *self {
            Intervals::Uniform(_) => i,
            Intervals::Periodic { count, .. } => i.rem_euclid(count),
        }
    }

    /// Whole periods from the origin's to interval `i`'s copy (0 without a
    /// period).
    #[inline]
    pub(crate) fn copy_of(&self, i: i64) -> i64 {
        match *self {
            Intervals::Uniform(_) => 0,
            Intervals::Periodic { count, .. } => i.div_euclid(count),
        }
    }

    /// The side of the narrowest interval.
    pub(crate) fn narrowest(&self) -> i64 {
        match *self {
            Intervals::Uniform(side) => side,
            Intervals::Periodic { period, count } => period / count,
        }
    }

    /// The period (0 without one).
    #[inline]
    pub(crate) fn period(&self) -> i64 {
        match *self {
            Intervals::Uniform(_) => 0,
            Intervals::Periodic { period, .. } => period,
        }
    }
}

/// Reads a period as JSON gives it: one number for all three axes (`128`),
/// an array of three (`[128, 128, 64]`), each deserialized as numbers, or
/// text in the one grammar of [`parse`] (`"128"`, `"128,128,64"`).
pub(crate) fn deserialize<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<[u32; 3]>, D::Error> {
    use serde::de::Error as _;
    let value = serde_json::Value::deserialize(d)?;
    let sides = match &value {
        serde_json::Value::Null => return Ok(None),
        serde_json::Value::String(s) => return parse(s).map(Some).map_err(D::Error::custom),
        serde_json::Value::Number(_) => u32::deserialize(&value).map(|p| [p; 3]),
        serde_json::Value::Array(_) => <[u32; 3]>::deserialize(&value),
        _ => return Err(D::Error::custom(not_a_period(&value))),
    };
    sides
        .map(Some)
        .map_err(|e| D::Error::custom(format!("{}: {e}", not_a_period(&value))))
}

fn not_a_period(given: impl std::fmt::Display) -> String {
    format!("period `{given}` is not one whole number or three (x,y,z)")
}

/// A period as text, the form of query strings and the command line:
/// one side (`128`) or three (`128,128,64`), decimal digits and commas
/// only — `^[0-9]+(,[0-9]+,[0-9]+)?$`, no brackets, signs or spaces. A
/// side too long for a number reads as the largest, which the range
/// check refuses.
pub fn parse(text: &str) -> Result<[u32; 3]> {
    let side = |s: &str| {
        (!s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
            .then(|| s.parse::<u32>().unwrap_or(u32::MAX))
    };
    let sides: Option<Vec<u32>> = text.split(',').map(side).collect();
    match sides.as_deref() {
        Some(&[p]) => Ok([p; 3]),
        Some(&[x, y, z]) => Ok([x, y, z]),
        _ => Err(Error::InvalidRequest(not_a_period(text))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_tile_the_line_and_repeat() {
        for (period, side) in [(16, 12), (10, 3), (4, 12), (100, 7), (32, 32)] {
            for iv in [
                Intervals::nearest(Some(period), side),
                Intervals::at_most(period, side),
            ] {
                let Intervals::Periodic { count, .. } = iv else {
                    unreachable!()
                };
                assert!(count >= 1);
                for x in -3 * period..3 * period {
                    let i = iv.index_of(x);
                    assert!(
                        iv.start(i) <= x && x < iv.start(i) + iv.size(i),
                        "{iv:?} {x}"
                    );
                    assert_eq!(iv.index_of(x + period), i + count, "{iv:?} {x}");
                    assert_eq!(iv.label(i), iv.label(i + count));
                    assert_eq!(iv.start(i + count), iv.start(i) + period);
                    assert!(iv.size(i) >= 1);
                }
            }
            let Intervals::Periodic { count, .. } = Intervals::at_most(period, side) else {
                unreachable!()
            };
            assert!((0..count).all(|i| Intervals::at_most(period, side).size(i) <= side));
        }
        let u = Intervals::Uniform(5);
        assert_eq!(
            (u.index_of(-1), u.start(-1), u.size(3), u.label(-7)),
            (-1, -5, 5, -7)
        );
    }

    #[test]
    fn periods_read_as_one_number_or_three() {
        assert_eq!(parse("128").unwrap(), [128; 3]);
        assert_eq!(parse("0128").unwrap(), [128; 3]);
        assert_eq!(parse("64,32,96").unwrap(), [64, 32, 96]);
        assert_eq!(parse("99999999999").unwrap(), [u32::MAX; 3]);
        // Exactly `^[0-9]+(,[0-9]+,[0-9]+)?$`, the pattern openapi.yaml
        // documents.
        for bad in [
            "",
            "1,2",
            "-32",
            "+32",
            "a",
            "1,2,3,4",
            "1.5",
            "1e2",
            " 128",
            "128 ",
            "64,32, 96",
            "[64,32,96]",
            "64,,96",
            "null",
            "1,2,3,",
        ] {
            assert!(parse(bad).is_err(), "{bad}");
        }
        let p: SynthParams = serde_json::from_str(r#"{"period": [64, 32, 96]}"#).unwrap();
        assert_eq!(p.period, Some([64, 32, 96]));
        let p: SynthParams = serde_json::from_str(r#"{"period": 64}"#).unwrap();
        assert_eq!(p.period, Some([64; 3]));
        for bad in [
            r#"{"period": [64, 32]}"#,
            r#"{"period": -64}"#,
            r#"{"period": 64.5}"#,
            r#"{"period": "[64,64,32]"}"#,
            r#"{"period": true}"#,
            r#"{"period": {"x": 64}}"#,
        ] {
            let e = serde_json::from_str::<SynthParams>(bad).unwrap_err();
            assert!(e.to_string().contains("period"), "{bad}: {e}");
        }
        let p: SynthParams = serde_json::from_str(r#"{"period": "64,64,32"}"#).unwrap();
        assert_eq!(p.period, Some([64, 64, 32]));
        let json = serde_json::to_string(&p).unwrap();
        assert!(json.ends_with(r#""period":[64,64,32]}"#), "{json}");
        assert_eq!(serde_json::from_str::<SynthParams>(&json).unwrap(), p);
        assert!(
            !serde_json::to_string(&SynthParams::default())
                .unwrap()
                .contains("period")
        );
    }

    #[test]
    fn periods_are_checked_against_the_levels() {
        let d = SynthParams::default();
        assert_eq!(multiple(4, &d), 32);
        assert_eq!(multiple(1, &d), 4);
        let three = SynthParams {
            subpass_side: 3,
            parity_levels: 1,
            ..d.clone()
        };
        assert_eq!(multiple(4, &three), 96);
        assert!(check([32, 64, 4096], 4, &d).is_ok());
        assert!(check([32, 48, 64], 4, &d).is_err());
        for (side, ok) in [(0, false), (1, true), (4096, true), (4097, false)] {
            let p = SynthParams {
                period: Some([side, 32, 32]),
                ..d.clone()
            };
            assert_eq!(p.validate().is_ok(), ok, "{side}");
        }
    }
}
