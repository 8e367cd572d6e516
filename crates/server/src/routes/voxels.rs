//! Voxel endpoints: axis slices and oblique cuts as PNG, regions and
//! aligned bricks as raw RGB8. Each handler turns its typed path and query
//! into a core [`Request`] and hands it to [`answer`].

use super::AppState;
use super::answer::{Encoding, answer, texture};
use super::params::{
    Int, NoQuery, Png, Raw, Stem, TextureId, TexturePath, Triple, TypedPath, TypedQuery, Vec3,
    document_query,
};
use crate::error::ApiError;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use solidtex_core::{
    Axis, COORD_LIMIT, CutPlane, Filter, MAX_REGION_VOXELS, MAX_SLICE_SIDE, Region, Request, Window,
};

/// A coordinate: any integer within ±2^31.
pub(super) type Coord = Int<{ -COORD_LIMIT }, COORD_LIMIT>;
/// A side of a slice, a cut or a frames window, 256 unless given.
pub(super) type Side = Int<1, { MAX_SLICE_SIDE as i64 }, 256>;
/// A side of a region, 64 unless given.
type RegionSide = Int<1, { MAX_REGION_VOXELS as i64 }, 64>;
/// A level of detail; the texture bounds it further (`max_lod`).
pub(super) type Lod = Int<0, { u32::MAX as i64 }>;

/// The path of a slice: `/v1/textures/{id}/slices/{axis}/{at}.png`.
#[derive(Deserialize)]
pub(super) struct SlicePath {
    id: String,
    axis: Axis,
    at: Stem<Png, Coord>,
}

/// Where on its plane a slice is asked for.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct SliceQuery {
    u0: Coord,
    v0: Coord,
    w: Side,
    h: Side,
    lod: Lod,
}

document_query!(SliceQuery {
    u0: "First u coordinate of the slice's window.",
    v0: "First v coordinate of the slice's window.",
    w: "Image width in pixels.",
    h: "Image height in pixels.",
    lod: LOD,
});

/// The `lod` query parameter's meaning.
pub(super) const LOD: &str = "Level of detail, 0 … the texture's `max_lod`; lod k serves level \
                              L−k, voxels 2^k finest voxels wide.";

/// `GET /v1/textures/{id}/slices/{axis}/{at}.png`
pub(super) async fn slice(
    State(s): State<AppState>,
    TypedPath(p): TypedPath<SlicePath>,
    TypedQuery(q): TypedQuery<SliceQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &p.id).await?;
    let window = Window::new(q.u0.get(), q.v0.get(), q.w.get_u32(), q.h.get_u32());
    let request = Request::slice(p.axis, p.at.0.get(), window)?;
    answer(&s, t, request, q.lod.get_u32(), Encoding::Png, &headers).await
}

/// An oblique plane: pixel (i, j) samples `origin + i·u + j·v`.
#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct CutQuery {
    origin: Vec3,
    u: Vec3,
    v: Vec3,
    w: Side,
    h: Side,
    lod: Lod,
    filter: Filter,
}

document_query!(CutQuery {
    origin: "Position of pixel (0, 0), `x,y,z`.",
    u: "Step per pixel to the right, `x,y,z`.",
    v: "Step per pixel downwards, `x,y,z`.",
    w: "Image width in pixels.",
    h: "Image height in pixels.",
    lod: LOD,
    filter: "`nearest`: the nearest voxel; `trilinear`: a blend of the eight around the \
             sample point.",
});

/// The xy plane from the origin, unless asked otherwise.
impl Default for CutQuery {
    fn default() -> CutQuery {
        CutQuery {
            origin: Vec3([0.0; 3]),
            u: Vec3([1.0, 0.0, 0.0]),
            v: Vec3([0.0, 1.0, 0.0]),
            w: Side::default(),
            h: Side::default(),
            lod: Lod::default(),
            filter: Filter::default(),
        }
    }
}

/// `GET /v1/textures/{id}/cut.png`
pub(super) async fn cut(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(q): TypedQuery<CutQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &id).await?;
    let plane = CutPlane {
        origin: q.origin.0,
        u: q.u.0,
        v: q.v.0,
        width: q.w.get_u32(),
        height: q.h.get_u32(),
    };
    let request = Request::cut(plane, q.filter)?;
    answer(&s, t, request, q.lod.get_u32(), Encoding::Png, &headers).await
}

/// A box of voxels.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct RegionQuery {
    x: Coord,
    y: Coord,
    z: Coord,
    w: RegionSide,
    h: RegionSide,
    d: RegionSide,
    lod: Lod,
}

document_query!(RegionQuery {
    x: "Lowest x.",
    y: "Lowest y.",
    z: "Lowest z.",
    w: "Extent along x.",
    h: "Extent along y.",
    d: "Extent along z.",
    lod: LOD,
});

/// `GET /v1/textures/{id}/region.raw`
pub(super) async fn region(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(q): TypedQuery<RegionQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &id).await?;
    let request = Request::region(Region {
        origin: [q.x, q.y, q.z].map(Int::get),
        size: [q.w, q.h, q.d].map(Int::get_u32),
    })?;
    answer(&s, t, request, q.lod.get_u32(), Encoding::Raw, &headers).await
}

/// The path of a brick: `/v1/textures/{id}/bricks/{lod}/{bx}_{by}_{bz}.raw`.
#[derive(Deserialize)]
pub(super) struct BrickPath {
    id: String,
    lod: Lod,
    brick: Stem<Raw, Triple>,
}

/// `GET /v1/textures/{id}/bricks/{lod}/{bx}_{by}_{bz}.raw`: the region of
/// edge E (the server's brick size) at (bx, by, bz)·E.
pub(super) async fn brick(
    State(s): State<AppState>,
    TypedPath(p): TypedPath<BrickPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &p.id).await?;
    let e = i64::from(s.brick_size);
    let (lo, hi) = (-COORD_LIMIT / e, (COORD_LIMIT + 1) / e - 1);
    let mut origin = [0i64; 3];
    for (a, name) in ["bx", "by", "bz"].into_iter().enumerate() {
        let b = p.brick.0.0[a];
        if !(lo..=hi).contains(&b) {
            return Err(ApiError::out_of_range(name, b, lo, hi));
        }
        origin[a] = b * e;
    }
    let request = Request::region(Region {
        origin,
        size: [s.brick_size; 3],
    })?;
    answer(&s, t, request, p.lod.get_u32(), Encoding::Raw, &headers).await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::routes::params::from_pairs;
    use proptest::prelude::*;

    fn parse<T: serde::de::DeserializeOwned>(raw: &str) -> Result<T, ApiError> {
        from_pairs(form_urlencoded::parse(raw.as_bytes()))
    }

    #[test]
    fn queries_take_their_defaults_and_refuse_strangers() {
        let q: SliceQuery = parse("").unwrap();
        assert_eq!((q.u0.get(), q.w.get(), q.lod.get()), (0, 256, 0));
        let q: CutQuery = parse("filter=trilinear&u=0,0,1").unwrap();
        assert_eq!(
            (q.filter, q.u.0, q.v.0),
            (Filter::Trilinear, [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
        );
        let q: RegionQuery = parse("d=7").unwrap();
        assert_eq!((q.w.get(), q.d.get()), (64, 7));
        let e = parse::<RegionQuery>("x0=5").unwrap_err();
        assert_eq!(e.code, "unknown_parameter");
        assert!(e.message.contains("x, y, z, w, h, d, lod"), "{}", e.message);
        assert_eq!(
            parse::<CutQuery>("filter=cubic").unwrap_err().code,
            "invalid_parameter"
        );
        assert_eq!(
            parse::<SliceQuery>("h=4097").unwrap_err().code,
            "out_of_range"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 512,
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        /// Any query string ends in a value or a 400, never a panic.
        #[test]
        fn query_parsing_never_panics(raw in "[a-z0-9=&%+.,eE-]{0,64}|\\PC{0,64}") {
            for e in [
                parse::<SliceQuery>(&raw).err(),
                parse::<CutQuery>(&raw).err(),
                parse::<RegionQuery>(&raw).err(),
            ].into_iter().flatten() {
                prop_assert_eq!(e.status, axum::http::StatusCode::BAD_REQUEST);
            }
        }
    }
}
