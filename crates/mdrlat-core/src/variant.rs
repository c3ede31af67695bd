//! The six network variants of the paper's ablation (Fig. 4, Table 2): named here, in the
//! shared vocabulary, so that every crate (the sweep, the evaluation's tables) can name a
//! variant without linking the networks (`mdrlat-nn` builds them).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which sensors the network reads and which modules it has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// The laser stream feeds the dueling head directly.
    LaserOnly,
    /// The depth stream feeds the dueling head directly.
    DepthOnly,
    /// Both streams, concatenated.
    Multi,
    /// `Multi` plus the auxiliary velocity-estimation task.
    MultiAt,
    /// `Multi` plus bilinear fusion.
    MultiBf,
    /// Bilinear fusion and the auxiliary task: the paper's method.
    Mdrlat,
}

/// An unknown variant name.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantParseError(pub String);

impl fmt::Display for VariantParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown variant '{}': expected one of laser-only, depth-only, multi, multi-at, \
             multi-bf, mdrlat",
            self.0
        )
    }
}

impl std::error::Error for VariantParseError {}

impl Variant {
    /// All variants, in the paper's order.
    pub const ALL: [Variant; 6] = [
        Variant::LaserOnly,
        Variant::DepthOnly,
        Variant::Multi,
        Variant::MultiAt,
        Variant::MultiBf,
        Variant::Mdrlat,
    ];

    /// The variant's name as used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Variant::LaserOnly => "laser-only",
            Variant::DepthOnly => "depth-only",
            Variant::Multi => "multi",
            Variant::MultiAt => "multi-at",
            Variant::MultiBf => "multi-bf",
            Variant::Mdrlat => "mdrlat",
        }
    }

    /// Reads the laser.
    pub fn uses_laser(self) -> bool {
        self != Variant::DepthOnly
    }

    /// Reads the depth camera.
    pub fn uses_depth(self) -> bool {
        self != Variant::LaserOnly
    }

    /// Has the bilinear fusion module.
    pub fn bilinear_fusion(self) -> bool {
        matches!(self, Variant::MultiBf | Variant::Mdrlat)
    }

    /// Has the auxiliary velocity-estimation task.
    pub fn auxiliary_task(self) -> bool {
        matches!(self, Variant::MultiAt | Variant::Mdrlat)
    }
}

impl fmt::Display for Variant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Variant {
    type Err = VariantParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Variant::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| VariantParseError(s.to_string()))
    }
}
