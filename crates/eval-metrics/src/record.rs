//! One evaluated run as a batch stores it: which run (method, sequence, direction, number),
//! whether it failed and its metrics.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::evaluate::Metrics;

/// Playback direction of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Direction {
    /// Played forwards (`fwd`).
    #[serde(rename = "fwd", alias = "forward", alias = "forwards")]
    Forward,
    /// Played backwards (`bwd`).
    #[serde(rename = "bwd", alias = "backward", alias = "backwards")]
    Backward,
}

impl Direction {
    /// `fwd` or `bwd`.
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Forward => "fwd",
            Direction::Backward => "bwd",
        }
    }
}

impl fmt::Display for Direction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Direction {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fwd" | "forward" | "forwards" => Ok(Direction::Forward),
            "bwd" | "backward" | "backwards" => Ok(Direction::Backward),
            _ => Err(format!("expected `fwd` or `bwd`, found `{s}`")),
        }
    }
}

/// Identifies one run of a batch.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct RunKey {
    /// Method name (the results tree's first level).
    pub method: String,
    /// Sequence name, e.g. `sequence_01`.
    pub sequence: String,
    /// Playback direction.
    pub direction: Direction,
    /// Run number.
    pub run: u32,
}

/// One evaluated run, as stored in results.csv.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Which run.
    pub key: RunKey,
    /// `None` when the run succeeded, else why it failed (empty when a results.csv without
    /// a `reason` column did not record why).
    pub failure: Option<String>,
    /// The metrics (infinite when failed).
    pub metrics: Metrics,
    /// Number of estimated poses.
    pub poses: usize,
    /// The field's other metrics computed for the run ([`crate::ExtraMetric`]), by column
    /// name (`ape_rmse`, ...; infinite where they could not be computed).
    #[serde(default)]
    pub extra: BTreeMap<String, f64>,
}

impl RunRecord {
    /// Whether the run succeeded.
    pub fn is_ok(&self) -> bool {
        self.failure.is_none()
    }
}
