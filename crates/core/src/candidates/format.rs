//! The `.stx` file: magic, format version, payload length, CRC-32 of the
//! payload, then the payload: parameters as JSON; exemplar pixels as given,
//! each followed by its feature mask if it has one; the layout of the
//! planes; per level the PCA bases, similarity sets and candidate triples
//! of the planes as analysed; the reference's blocks of triples (level,
//! side, then every voxel's triple); and, since version 6, a count of
//! levels of usage penalties, which histogram matching wrote. It was
//! removed, so the count is written 0 and a file with penalties is
//! refused, as is one whose parameters use a removed knob
//! (`histogram_matching`, `glcp_weight`). Versions 1 to 4 (without the
//! blocks, the masks or the layout) are no longer read: such a file is
//! refused with a request to precompute again, and the server does so on
//! its own for a stored texture, from its stored exemplar. Derived data
//! (stacks, appearance vectors, quantised neighbourhoods) is recomputed on
//! load, deterministically. Every read is bounds-checked: a truncated or
//! corrupt file is an error, never a panic or a wrong result.

use super::{Candidates, PlaneCandidates, PrecomputeReport, StoredLevel};
use crate::analysis::appearance::Pca;
use crate::analysis::exemplar::{Exemplar, ExemplarSet};
use crate::analysis::orientation::{Grain, Layout};
use crate::error::{CorruptKind, Error, Result};
use crate::params::{AnalysisParams, Arrangement, Orientation};

const MAGIC: &[u8; 8] = b"SOLIDTEX";
const VERSION: u32 = 6;
/// The oldest version read.
const OLDEST: u32 = 5;
const HEADER: usize = 8 + 4 + 8 + 4;

struct Writer(Vec<u8>);

impl Writer {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.0.extend_from_slice(b);
    }
    fn pca(&mut self, p: &Pca) {
        self.u32(p.input as u32);
        self.u32(p.dims as u32);
        for &v in p.mean.iter().chain(&p.basis) {
            self.f32(v);
        }
    }
    fn coord(&mut self, c: u32, wide: bool) {
        if wide {
            self.u32(c);
        } else {
            self.0.extend_from_slice(&(c as u16).to_le_bytes());
        }
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

fn invalid(s: &str) -> Error {
    Error::CorruptFile(CorruptKind::Invalid(s.to_string()))
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or(Error::CorruptFile(CorruptKind::Truncated))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn f32(&mut self) -> Result<f32> {
        let v = f32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes"));
        if v.is_finite() {
            Ok(v)
        } else {
            Err(invalid("non-finite number"))
        }
    }
    fn bytes(&mut self) -> Result<&'a [u8]> {
        let n = self.u32()? as usize;
        self.take(n)
    }
    fn pca(&mut self, input: usize, max_dims: usize) -> Result<Pca> {
        let i = self.u32()? as usize;
        let dims = self.u32()? as usize;
        if i != input || dims == 0 || dims > max_dims {
            return Err(invalid("pca shape"));
        }
        let mean = (0..input).map(|_| self.f32()).collect::<Result<Vec<_>>>()?;
        let basis = (0..input * dims)
            .map(|_| self.f32())
            .collect::<Result<Vec<_>>>()?;
        Ok(Pca {
            input,
            dims,
            mean,
            basis,
        })
    }
    fn coord(&mut self, wide: bool, limit: u32) -> Result<u32> {
        let c = if wide {
            self.u32()?
        } else {
            u16::from_le_bytes(self.take(2)?.try_into().expect("2 bytes")) as u32
        };
        if c < limit {
            Ok(c)
        } else {
            Err(invalid("coordinate out of range"))
        }
    }
}

pub(super) fn encode(c: &Candidates) -> Vec<u8> {
    encode_version(c, VERSION)
}

/// [`encode`] in the layout of `version` ([`OLDEST`] or later; older
/// ones for the tests of reading them).
fn encode_version(c: &Candidates, version: u32) -> Vec<u8> {
    let single = c.exemplars.is_single();
    let planes = if c.analysed.is_single() { 1 } else { 3 };
    let npx = c.dims.len() as u32;
    let wide = npx > u16::MAX as u32 + 1;
    let mut w = Writer(Vec::new());
    // The struct's own field order, whatever map serde_json keeps.
    w.bytes(&serde_json::to_vec(&c.params).expect("params serialise"));
    w.u8(single as u8);
    w.u32(c.dims.w);
    w.u32(c.dims.h);
    for p in 0..if single { 1 } else { 3 } {
        let e = c.exemplars.plane(p);
        w.0.extend_from_slice(&e.to_rgb_bytes());
        match e.feature_mask() {
            Some(mask) => {
                w.u8(1);
                w.0.extend(mask.iter().map(|&f| f as u8));
            }
            None => w.u8(0),
        }
    }
    let layout = &c.layout;
    for r in layout.arrangement.rotate {
        w.u8((r / 90) as u8);
    }
    for v in layout.arrangement.weights {
        w.f32(v);
    }
    w.u8(layout.detected as u8);
    w.f32(layout.grain.coherence);
    w.f32(layout.grain.degrees);
    for l in c.stored_levels() {
        for p in 0..planes {
            w.pca(&l.appearance_pca[p]);
        }
        w.u32(l.k2 as u32);
        for p in 0..planes {
            for &s in &l.similar[p] {
                w.coord(s, wide);
            }
        }
        for p in 0..planes {
            let cand = &l.candidates[p];
            for px in 0..npx {
                w.u8(cand.range(px).len() as u8);
            }
            for (t, e) in cand.triples.iter().zip(&cand.errors) {
                for (j, &coord) in t.iter().enumerate() {
                    if j != p {
                        w.coord(coord, wide);
                    }
                }
                w.f32(*e);
            }
        }
    }
    w.u32(c.blocks().len() as u32);
    for b in c.blocks() {
        w.u32(b.level);
        w.u32(b.side);
        for t in &b.triples {
            for &coord in t {
                w.coord(coord, wide);
            }
        }
    }
    if version >= 6 {
        // No usage penalties (see the module's documentation).
        w.u32(0);
    }
    let payload = w.0;
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

pub(super) fn decode(bytes: &[u8]) -> Result<Candidates> {
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(Error::CorruptFile(CorruptKind::BadMagic));
    }
    if bytes.len() < HEADER {
        return Err(Error::CorruptFile(CorruptKind::Truncated));
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if (1..OLDEST).contains(&version) {
        return Err(invalid(&format!(
            "format version {version} is no longer read (the oldest read is {OLDEST}): \
             precompute the texture again"
        )));
    }
    if !(OLDEST..=VERSION).contains(&version) {
        return Err(Error::CorruptFile(CorruptKind::Version(version)));
    }
    let len = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
    let crc = u32::from_le_bytes(bytes[20..24].try_into().expect("4 bytes"));
    let payload = &bytes[HEADER..];
    if (payload.len() as u64) < len {
        return Err(Error::CorruptFile(CorruptKind::Truncated));
    }
    if payload.len() as u64 > len {
        return Err(invalid("trailing bytes"));
    }
    if crc32fast::hash(payload) != crc {
        return Err(Error::CorruptFile(CorruptKind::Checksum));
    }
    let mut r = Reader {
        buf: payload,
        pos: 0,
    };
    let mut params: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(r.bytes()?).map_err(|e| invalid(&format!("params: {e}")))?;
    crate::params::knobs::strip_removed(&mut params).map_err(|e| invalid(&e))?;
    let params: AnalysisParams =
        serde_json::from_value(params.into()).map_err(|e| invalid(&format!("params: {e}")))?;
    params.validate().map_err(|e| invalid(&e.to_string()))?;
    let single = match r.u8()? {
        0 => false,
        1 => true,
        _ => return Err(invalid("plane flag")),
    };
    let width = r.u32()?;
    let height = r.u32()?;
    let mut exemplars = Vec::new();
    for _ in 0..if single { 1 } else { 3 } {
        let n = (width as usize)
            .checked_mul(height as usize)
            .and_then(|n| n.checked_mul(3))
            .ok_or_else(|| invalid("size"))?;
        let mut e =
            Exemplar::from_rgb(width, height, r.take(n)?).map_err(|e| invalid(&e.to_string()))?;
        let masked = match r.u8()? {
            0 => false,
            1 => true,
            _ => return Err(invalid("feature mask flag")),
        };
        if masked {
            let mask = r
                .take(n / 3)?
                .iter()
                .map(|&b| match b {
                    0 => Ok(false),
                    1 => Ok(true),
                    _ => Err(invalid("feature mask")),
                })
                .collect::<Result<Vec<bool>>>()?;
            e = e
                .with_feature_mask(mask)
                .map_err(|e| invalid(&e.to_string()))?;
        }
        exemplars.push(e);
    }
    let set = if single {
        ExemplarSet::single(exemplars.pop().expect("one"))
    } else {
        let zx = exemplars.pop().expect("three");
        let yz = exemplars.pop().expect("three");
        let xy = exemplars.pop().expect("three");
        ExemplarSet::triple(xy, yz, zx).map_err(|e| invalid(&e.to_string()))?
    };
    if !single && set.is_single() {
        return Err(invalid("plane flag"));
    }
    let layout = read_layout(&mut r, &params)?;
    let analysed = layout.apply(&set).map_err(|_| invalid("layout"))?;
    let single = analysed.is_single();
    let planes = if single { 1 } else { 3 };
    let npx = width * height;
    let wide = npx > u16::MAX as u32 + 1;
    let channels = if params.feature_weight > 0.0 { 4 } else { 3 };
    let app_input = (params.neighbourhood * params.neighbourhood) as usize * channels;
    let mut levels = Vec::new();
    for _ in 0..params.levels {
        let mut pcas = Vec::new();
        for _ in 0..planes {
            pcas.push(r.pca(app_input, params.pca_dims as usize)?);
        }
        let k2 = r.u32()? as usize;
        if k2 == 0 || k2 > 8 {
            return Err(invalid("similarity set size"));
        }
        let mut similar = Vec::new();
        for _ in 0..planes {
            let s = (0..npx as usize * k2)
                .map(|_| r.coord(wide, npx))
                .collect::<Result<Vec<_>>>()?;
            similar.push(s);
        }
        let mut cands = Vec::new();
        for p in 0..planes {
            let counts = r.take(npx as usize)?.to_vec();
            let mut offsets = Vec::with_capacity(npx as usize + 1);
            offsets.push(0u32);
            let mut triples = Vec::new();
            let mut errors = Vec::new();
            for (px, &n) in counts.iter().enumerate() {
                if n as u32 > params.max_candidates {
                    return Err(invalid("candidate count"));
                }
                for _ in 0..n {
                    let mut t = [0u32; 3];
                    for (j, slot) in t.iter_mut().enumerate() {
                        *slot = if j == p {
                            px as u32
                        } else {
                            r.coord(wide, npx)?
                        };
                    }
                    triples.push(t);
                    errors.push(r.f32()?);
                }
                offsets.push(triples.len() as u32);
            }
            cands.push(PlaneCandidates {
                offsets: std::sync::Arc::new(offsets),
                triples,
                errors,
            });
        }
        let (pcas, similar, cands) = if single {
            let c = cands.pop().expect("one");
            let p = pcas.pop().expect("one");
            let s = similar.pop().expect("one");
            (
                [p.clone(), p.clone(), p],
                [s.clone(), s.clone(), s],
                [c.clone(), c.rotated(1), c.rotated(2)],
            )
        } else {
            (
                pcas.try_into().expect("three"),
                similar.try_into().expect("three"),
                cands.try_into().expect("three"),
            )
        };
        levels.push(StoredLevel {
            appearance_pca: pcas,
            candidates: cands,
            similar,
            k2,
        });
    }
    let mut blocks = Vec::new();
    let count = r.u32()?;
    if count > params.levels {
        return Err(invalid("block count"));
    }
    for _ in 0..count {
        let level = r.u32()?;
        let side = r.u32()?;
        if side == 0 || side > crate::reference::MAX_REFERENCE_SIZE {
            return Err(invalid("block side"));
        }
        let voxels = (side as usize).pow(3);
        // Bounded before allocating: each triple takes at least six
        // bytes of what is left.
        if voxels.saturating_mul(6) > payload.len() - r.pos {
            return Err(Error::CorruptFile(CorruptKind::Truncated));
        }
        let mut triples = Vec::with_capacity(voxels);
        for _ in 0..voxels {
            triples.push([
                r.coord(wide, npx)?,
                r.coord(wide, npx)?,
                r.coord(wide, npx)?,
            ]);
        }
        blocks.push(crate::reference::TripleBlock {
            side,
            level,
            triples,
        });
    }
    if version >= 6 && r.u32()? != 0 {
        return Err(invalid(
            "made with `histogram_matching`, which this version no longer has: \
             precompute the texture again",
        ));
    }
    if r.pos != payload.len() {
        return Err(invalid("trailing bytes"));
    }
    Candidates::from_stored(
        set,
        params,
        layout,
        levels,
        blocks,
        PrecomputeReport::default(),
    )
}

/// The layout record, which must agree with an orientation that was given.
fn read_layout(r: &mut Reader, params: &AnalysisParams) -> Result<Layout> {
    let mut rotate = [0u32; 3];
    for q in &mut rotate {
        *q = match r.u8()? {
            turns @ 0..=3 => turns as u32 * 90,
            _ => return Err(invalid("rotation")),
        };
    }
    let mut weights = [0f32; 3];
    for w in &mut weights {
        *w = r.f32()?;
    }
    let arrangement = Arrangement { rotate, weights };
    arrangement
        .validate()
        .map_err(|e| invalid(&e.to_string()))?;
    let detected = match r.u8()? {
        0 => false,
        1 => true,
        _ => return Err(invalid("detection flag")),
    };
    let grain = Grain {
        coherence: r.f32()?,
        degrees: r.f32()?,
    };
    let expected = match params.orientation {
        Orientation::Auto => arrangement,
        Orientation::None => Arrangement::default(),
        Orientation::Given(a) => a,
    };
    if arrangement != expected {
        return Err(invalid("layout differs from the orientation parameter"));
    }
    Ok(Layout {
        arrangement,
        grain,
        detected,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Horizontal stripes with a little noise: strongly oriented along u.
    fn grain(side: u32) -> Exemplar {
        let rgb: Vec<u8> = (0..side * side)
            .flat_map(|i| {
                let (u, v) = (i % side, i / side);
                let l = ((v % 6) * 35 + (u * 7 + v * 3) % 11) as u8;
                [l, l / 2 + 60, 90]
            })
            .collect();
        Exemplar::from_rgb(side, side, &rgb).unwrap()
    }

    fn compute(e: Exemplar, orientation: Orientation) -> Candidates {
        let params = AnalysisParams {
            levels: 2,
            orientation,
            ..AnalysisParams::default()
        };
        Candidates::compute(&ExemplarSet::single(e), &params, &|_, _| {}).unwrap()
    }

    /// A payload's header: magic, `version`, length and checksum.
    fn with_header(version: u32, payload: &[u8]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&version.to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
        out.extend_from_slice(payload);
        out
    }

    /// Where the layout record starts in the payload of `c`'s file (its
    /// exemplars without feature masks).
    fn layout_at(c: &Candidates, payload: &[u8]) -> usize {
        let json = u32::from_le_bytes(payload[..4].try_into().unwrap()) as usize;
        let planes = if c.exemplars.is_single() { 1 } else { 3 };
        4 + json + 1 + 8 + planes * (c.dims.len() * 3 + 1)
    }

    #[test]
    fn files_that_need_a_removed_knob_are_refused() {
        let c = compute(grain(16), Orientation::None);
        let bytes = c.to_bytes();
        let payload = &bytes[HEADER..];
        // Usage penalties (a count of levels above 0) are refused.
        let count_at = payload.len() - 4;
        assert_eq!(payload[count_at..], 0u32.to_le_bytes());
        let mut with_penalties = payload.to_vec();
        with_penalties[count_at..].copy_from_slice(&2u32.to_le_bytes());
        let err = decode(&with_header(VERSION, &with_penalties)).unwrap_err();
        assert!(err.to_string().contains("histogram_matching"), "{err}");
        // A removed knob in the parameters: at 0 it reads as without it,
        // above 0 the file is refused.
        let json_len = u32::from_le_bytes(payload[..4].try_into().unwrap()) as usize;
        let json: serde_json::Value = serde_json::from_slice(&payload[4..4 + json_len]).unwrap();
        for (key, value, loads) in [
            ("glcp_weight", 0.0, true),
            ("glcp_weight", 0.3, false),
            ("histogram_matching", 0.0, true),
            ("histogram_matching", 1.0, false),
        ] {
            let mut j = json.clone();
            j[key] = serde_json::json!(value);
            let text = serde_json::to_vec(&j).unwrap();
            let mut p = (text.len() as u32).to_le_bytes().to_vec();
            p.extend_from_slice(&text);
            p.extend_from_slice(&payload[4 + json_len..]);
            match decode(&with_header(VERSION, &p)) {
                Ok(back) => {
                    assert!(loads, "{key} {value}");
                    assert_eq!(back.params(), c.params());
                }
                Err(e) => {
                    assert!(!loads, "{key} {value}: {e}");
                    assert!(e.to_string().contains(key), "{e}");
                }
            }
        }
    }

    #[test]
    fn the_reference_blocks_read_as_written_and_broken_ones_are_refused() {
        let params = AnalysisParams {
            levels: 2,
            initialisation: crate::Initialisation::Reference,
            reference_level: Some(0),
            ..AnalysisParams::default()
        };
        let c = Candidates::compute(&ExemplarSet::single(grain(16)), &params, &|_, _| {}).unwrap();
        assert_eq!(
            c.blocks().iter().map(|b| b.level).collect::<Vec<_>>(),
            [0, 1]
        );
        let bytes = encode(&c);
        let loaded = decode(&bytes).unwrap();
        assert_eq!(loaded.blocks(), c.blocks());
        // A block's side that claims more voxels than the file holds is
        // refused before anything is allocated for it.
        let blocks_at = bytes.len()
            - c.blocks()
                .iter()
                .map(|b| 8 + b.triples.len() * 6)
                .sum::<usize>()
            - 4
            // The usage penalties' count (always 0) follows the blocks.
            - 4;
        let mut payload = bytes[HEADER..].to_vec();
        let side_at = blocks_at - HEADER + 4 + 4;
        payload[side_at..side_at + 4].copy_from_slice(&200u32.to_le_bytes());
        assert!(decode(&with_header(VERSION, &payload)).is_err());
        // Blocks that do not match the parameters' levels are refused.
        let mut payload = bytes[HEADER..].to_vec();
        let level_at = blocks_at - HEADER + 4;
        payload[level_at..level_at + 4].copy_from_slice(&1u32.to_le_bytes());
        assert!(decode(&with_header(VERSION, &payload)).is_err());
    }

    #[test]
    fn version_5_loads_and_older_or_newer_versions_are_refused() {
        let params = AnalysisParams {
            levels: 2,
            ..AnalysisParams::default()
        };
        let c = Candidates::compute(&ExemplarSet::single(grain(16)), &params, &|_, _| {}).unwrap();
        let now = encode(&c);
        // Version 5 lacks the penalty count only.
        let v5 = encode_version(&c, 5);
        assert_eq!(v5.len() + 4, now.len());
        assert_eq!(encode(&decode(&v5).unwrap()), now);
        for old in 1..OLDEST {
            let e = decode(&with_header(old, &now[HEADER..])).unwrap_err();
            assert!(
                e.to_string().contains(&format!(
                    "format version {old} is no longer read (the oldest read is 5): \
                     precompute the texture again"
                )),
                "{e}"
            );
        }
        assert!(matches!(
            decode(&with_header(VERSION + 1, &now[HEADER..])),
            Err(Error::CorruptFile(CorruptKind::Version(_)))
        ));
    }

    #[test]
    fn a_feature_channel_widens_the_appearance_vectors_and_round_trips() {
        let params = AnalysisParams {
            levels: 2,
            feature_weight: 1.0,
            ..AnalysisParams::default()
        };
        let c = Candidates::compute(&ExemplarSet::single(grain(32)), &params, &|_, _| {}).unwrap();
        let n = params.neighbourhood as usize;
        for k in 0..2 {
            assert_eq!(c.level(k).appearance[0].pca.input, n * n * 4);
            assert_eq!(c.level(k).appearance[0].channels, 4);
        }
        let bytes = encode(&c);
        let back = decode(&bytes).unwrap();
        assert_eq!(back.params().feature_weight, 1.0);
        assert_eq!(back.level(1).appearance, c.level(1).appearance);
        assert_eq!(encode(&back), bytes);
        // Without the channel the parameter is not written: files and ids
        // of textures without it stay as they were.
        let plain = compute(grain(32), Orientation::None);
        assert_eq!(plain.level(0).appearance[0].pca.input, n * n * 3);
        let json = serde_json::to_string(plain.params()).unwrap();
        assert!(!json.contains("feature_weight"), "{json}");
        assert_ne!(
            plain.level(0).appearance[0].vectors,
            c.level(0).appearance[0].vectors
        );
    }

    #[test]
    fn a_feature_mask_round_trips_and_changes_the_candidates() {
        let params = AnalysisParams {
            levels: 2,
            feature_weight: 1.0,
            ..AnalysisParams::default()
        };
        let e = grain(32);
        // A mask that no colour threshold would find: a diagonal band.
        let mask: Vec<bool> = (0..32 * 32).map(|i| (i % 32 + i / 32) % 16 < 3).collect();
        let masked = e.clone().with_feature_mask(mask.clone()).unwrap();
        let c = Candidates::compute(&ExemplarSet::single(masked), &params, &|_, _| {}).unwrap();
        let bytes = encode(&c);
        let back = decode(&bytes).unwrap();
        assert_eq!(back.exemplars().plane(0).feature_mask(), Some(&mask[..]));
        assert_eq!(back.level(0).appearance, c.level(0).appearance);
        assert_eq!(encode(&back), bytes);
        let auto = Candidates::compute(&ExemplarSet::single(e), &params, &|_, _| {}).unwrap();
        assert_ne!(
            auto.level(0).appearance[0].vectors,
            c.level(0).appearance[0].vectors
        );
        // A mask flag other than 0 or 1 is a corrupt file.
        let mut payload = bytes[HEADER..].to_vec();
        // Right after the pixels, where an unmasked file's layout would
        // start less its one flag byte.
        let flag = layout_at(&c, &payload) - 1;
        assert_eq!(payload[flag], 1);
        payload[flag] = 2;
        assert!(matches!(
            decode(&with_header(VERSION, &payload)),
            Err(Error::CorruptFile(CorruptKind::Invalid(_)))
        ));
        // Without the channel nothing would read the mask: refused.
        let plain = AnalysisParams {
            feature_weight: 0.0,
            ..params
        };
        let masked = grain(32).with_feature_mask(mask).unwrap();
        assert!(matches!(
            Candidates::compute(&ExemplarSet::single(masked), &plain, &|_, _| {}),
            Err(Error::InvalidRequest(_))
        ));
    }

    #[test]
    fn a_layout_round_trips_and_must_agree_with_a_given_orientation() {
        let given = Orientation::Given(Arrangement {
            rotate: [0, 270, 0],
            weights: [1.0, 1.0, 0.5],
        });
        for orientation in [Orientation::Auto, given] {
            let c = compute(grain(16), orientation);
            assert!(!c.analysed().is_single());
            assert!(c.exemplars().is_single());
            let bytes = encode(&c);
            let back = decode(&bytes).unwrap();
            assert_eq!(back.layout(), c.layout());
            assert_eq!(back.analysed(), c.analysed());
            assert_eq!(encode(&back), bytes);
        }
        let c = compute(grain(16), given);
        let mut payload = encode(&c)[HEADER..].to_vec();
        let at = layout_at(&c, &payload);
        assert_eq!(payload[at + 1], 3);
        payload[at + 1] = 1;
        assert!(matches!(
            decode(&with_header(VERSION, &payload)),
            Err(Error::CorruptFile(CorruptKind::Invalid(_)))
        ));
    }
}
