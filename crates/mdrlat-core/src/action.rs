//! The discrete action space of the paper (Table 1).

use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use std::fmt;

/// A (linear, angular) velocity pair in the robot frame: metres per second and radians per
/// second, counter-clockwise positive.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Velocity {
    /// Linear velocity along the robot's heading, m/s.
    pub v: f32,
    /// Angular velocity about the vertical axis, rad/s (counter-clockwise positive).
    pub w: f32,
}

impl Velocity {
    /// A velocity pair.
    pub const fn new(v: f32, w: f32) -> Self {
        Self { v, w }
    }
}

/// Paper Table 1: the ten velocity commands, indexed by action.
#[doc(alias = "table1")]
pub const TABLE_1: [Velocity; 10] = [
    Velocity::new(0.5, -PI / 12.0),
    Velocity::new(0.5, 0.0),
    Velocity::new(0.5, PI / 12.0),
    Velocity::new(0.2, -PI / 6.0),
    Velocity::new(0.2, -PI / 12.0),
    Velocity::new(0.2, 0.0),
    Velocity::new(0.2, PI / 12.0),
    Velocity::new(0.2, PI / 6.0),
    Velocity::new(0.0, -PI / 3.0),
    Velocity::new(0.0, PI / 3.0),
];

/// One of the ten discrete actions of Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub struct Action(u8);

impl Action {
    /// Number of discrete actions.
    pub const COUNT: usize = TABLE_1.len();

    /// The action with this index, or `None` if `index >= 10`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < Self::COUNT { Some(Self(index as u8)) } else { None }
    }

    /// The action's index in Table 1.
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// The Table 1 action nearest a velocity (each component scaled by its largest value
    /// in the table; the first on ties).
    pub fn nearest(cmd: Velocity) -> Self {
        let v_max = TABLE_1.iter().map(|a| a.v).fold(f32::MIN_POSITIVE, f32::max);
        let w_max = TABLE_1.iter().map(|a| a.w.abs()).fold(f32::MIN_POSITIVE, f32::max);
        let d = |a: &Velocity| ((a.v - cmd.v) / v_max).powi(2) + ((a.w - cmd.w) / w_max).powi(2);
        let best = (0..Self::COUNT).min_by(|&i, &j| d(&TABLE_1[i]).total_cmp(&d(&TABLE_1[j])));
        Self(best.unwrap_or(0) as u8)
    }

    /// The velocity command of this action (Table 1).
    pub const fn command(self) -> Velocity {
        TABLE_1[self.0 as usize]
    }

    /// All actions in order.
    pub fn all() -> impl Iterator<Item = Action> {
        (0..Self::COUNT as u8).map(Action)
    }

    /// The largest |v| and |ω| of Table 1: the limits a real robot's commands are clamped to.
    pub fn command_limits() -> Velocity {
        TABLE_1
            .iter()
            .fold(Velocity::default(), |m, c| Velocity::new(m.v.max(c.v.abs()), m.w.max(c.w.abs())))
    }
}

impl TryFrom<u8> for Action {
    type Error = String;
    fn try_from(value: u8) -> Result<Self, Self::Error> {
        Action::new(value as usize).ok_or_else(|| format!("action {value} is not in 0..=9"))
    }
}

impl From<Action> for u8 {
    fn from(a: Action) -> u8 {
        a.0
    }
}

impl fmt::Display for Action {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nearest_action_of_a_table_1_velocity_is_itself() {
        for (i, v) in TABLE_1.iter().enumerate() {
            assert_eq!(Action::nearest(*v).index(), i);
        }
        assert_eq!(Action::nearest(Velocity::new(0.45, 0.02)).index(), 1);
        assert_eq!(Action::nearest(Velocity::new(0.0, -3.0)).command().v, 0.0, "a turn in place");
    }

    #[test]
    fn table_1_matches_the_paper() {
        let v: Vec<f32> = TABLE_1.iter().map(|c| c.v).collect();
        assert_eq!(v, [0.5, 0.5, 0.5, 0.2, 0.2, 0.2, 0.2, 0.2, 0.0, 0.0]);
        let w_over_pi: Vec<f32> = TABLE_1.iter().map(|c| c.w / PI).collect();
        let expect = [
            -1.0 / 12.0,
            0.0,
            1.0 / 12.0,
            -1.0 / 6.0,
            -1.0 / 12.0,
            0.0,
            1.0 / 12.0,
            1.0 / 6.0,
            -1.0 / 3.0,
            1.0 / 3.0,
        ];
        for (a, b) in w_over_pi.iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn action_indices_are_checked() {
        assert!(Action::new(9).is_some());
        assert!(Action::new(10).is_none());
        assert!(Action::try_from(200u8).is_err());
        assert_eq!(Action::all().count(), 10);
        let lim = Action::command_limits();
        assert_eq!(lim.v, 0.5);
        assert!((lim.w - PI / 3.0).abs() < 1e-6);
    }
}
