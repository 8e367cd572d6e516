//! The `.stx` file: magic, format version, payload length, CRC-32 of the
//! payload, then the payload (parameters as JSON, exemplar pixels, and per
//! level the PCA bases, similarity sets and candidate triples). Derived data
//! (stacks, appearance vectors, quantised neighbourhoods) is recomputed on
//! load, deterministically. Every read is bounds-checked: a truncated or
//! corrupt file is an error, never a panic or a wrong result.

use super::{Candidates, PlaneCandidates, PrecomputeReport, StoredLevel};
use crate::appearance::Pca;
use crate::error::{CorruptKind, Error, Result};
use crate::exemplar::{Exemplar, ExemplarSet};
use crate::params::AnalysisParams;

const MAGIC: &[u8; 8] = b"SOLIDTEX";
const VERSION: u32 = 1;
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
    let single = c.exemplars.is_single();
    let planes = if single { 1 } else { 3 };
    let npx = c.dims.len() as u32;
    let wide = npx > u16::MAX as u32 + 1;
    let mut w = Writer(Vec::new());
    w.bytes(&serde_json::to_vec(&c.params).expect("params serialise"));
    w.u8(single as u8);
    w.u32(c.dims.w);
    w.u32(c.dims.h);
    for p in 0..planes {
        w.0.extend_from_slice(&c.exemplars.plane(p).to_rgb_bytes());
    }
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
        w.pca(&l.joint_pca);
        w.f32(l.quant_scale);
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
    let payload = w.0;
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
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
    if version != VERSION {
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
    let params: AnalysisParams =
        serde_json::from_slice(r.bytes()?).map_err(|e| invalid(&format!("params: {e}")))?;
    params.validate().map_err(|e| invalid(&e.to_string()))?;
    let single = match r.u8()? {
        0 => false,
        1 => true,
        _ => return Err(invalid("plane flag")),
    };
    let width = r.u32()?;
    let height = r.u32()?;
    let planes = if single { 1 } else { 3 };
    let mut exemplars = Vec::new();
    for _ in 0..planes {
        let n = (width as usize)
            .checked_mul(height as usize)
            .and_then(|n| n.checked_mul(3))
            .ok_or_else(|| invalid("size"))?;
        let e =
            Exemplar::from_rgb(width, height, r.take(n)?).map_err(|e| invalid(&e.to_string()))?;
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
    let npx = width * height;
    let wide = npx > u16::MAX as u32 + 1;
    let app_input = (params.neighbourhood * params.neighbourhood * 3) as usize;
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
        let joint_input: usize =
            pcas.iter().map(|p| p.dims).sum::<usize>() * if single { 3 } else { 1 };
        let joint_pca = r.pca(joint_input, 16)?;
        let quant_scale = r.f32()?;
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
            joint_pca,
            quant_scale,
        });
    }
    if r.pos != payload.len() {
        return Err(invalid("trailing bytes"));
    }
    Candidates::from_stored(set, params, levels, PrecomputeReport::default())
}
