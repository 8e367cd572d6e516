//! Exemplar analysis, the first stage of Dong et al.'s candidate
//! pre-computation: the exemplars themselves (and reading them from image
//! files), their Gaussian stacks, the
//! appearance space every neighbourhood is matched in, the optional
//! feature-distance channel, and how an anisotropic exemplar is laid on
//! the three planes (Zhang et al. §6.1). Nothing here knows about 3D
//! candidates or synthesis.

pub mod appearance;
pub mod decode;
pub mod exemplar;
pub mod feature;
pub mod orientation;
pub mod stack;
