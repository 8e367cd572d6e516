//! Frames from sketched curves, interpolated over a grid (Zhang et al. §3).

use super::Frame;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// One sketched curve: a polyline on a reference plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    /// The polyline's points, in voxels of the finest level.
    pub points: Vec<[f64; 3]>,
    /// Normal of the reference plane the curve lies on.
    pub normal: [f64; 3],
    /// The local axis that runs along the curve: `x` (the default), `y`
    /// or `z`. The normal becomes the axis two after it (z for x, x for y,
    /// y for z), so the frame stays right-handed.
    #[serde(default)]
    pub along: Along,
}

/// A local axis, by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Along {
    /// Local x.
    #[default]
    X,
    /// Local y.
    Y,
    /// Local z.
    Z,
}

/// Curves whose frames are interpolated into a field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sketch {
    /// The curves, in the order they were drawn.
    pub curves: Vec<Curve>,
}

impl Sketch {
    /// Checks the curves.
    pub fn validate(&self) -> Result<()> {
        Err(Error::InvalidRequest(
            "field: sketch fields are not supported yet".into(),
        ))
    }

    /// Interpolates the curves' frames over a grid.
    pub(crate) fn solve(&self) -> Result<SolvedSketch> {
        self.validate()?;
        Ok(SolvedSketch {})
    }
}

/// A sketch's frames, solved on a grid.
pub(crate) struct SolvedSketch {}

impl SolvedSketch {
    /// The frame at `p`.
    pub(crate) fn frame(&self, _p: [f64; 3]) -> Frame {
        super::IDENTITY
    }
}
