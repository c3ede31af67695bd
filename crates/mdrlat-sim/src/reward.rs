//! The reward of paper eqs. (3)–(6), and the navigation task's.

use crate::config::{NavConfig, RewardConfig};
use mdrlat_core::Velocity;

/// The three terms of eq. (3), kept apart for logging and tests.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RewardTerms {
    /// Eq. (4): the collision penalty, or `λ_c·v²·cos(v·ω)`.
    pub r_c: f32,
    /// Eq. (5): `λ_d·0.4/d_min` when `0.2 < d_min < 0.4`, else 0.
    pub r_d: f32,
    /// Eq. (6): `λ_ω·|ω_t − ω_{t−1}|` when `ω_t·ω_{t−1} < 0`, else 0.
    pub r_w: f32,
    /// The navigation task's goal term (arrival bonus or progress); 0 in obstacle avoidance.
    pub r_g: f32,
}

impl RewardTerms {
    /// Eq. (3): `r_t = r_c + r_d + r_ω` (`+ r_g`, 0 unless navigating).
    pub fn total(&self) -> f32 {
        self.r_c + self.r_d + self.r_w + self.r_g
    }
}

/// Paper eqs. (3)–(6), with `(v, ω)` the true velocity at `t`, `w_prev` the true angular
/// velocity at `t − 1` and `d_min` the smallest laser range. A collision (bumper, pedestrian
/// or `d_min` below the collision range) gives only the collision reward.
#[doc(alias = "eq3")]
#[doc(alias = "eq4")]
#[doc(alias = "eq5")]
#[doc(alias = "eq6")]
pub fn reward(
    cfg: &RewardConfig,
    collided: bool,
    vel: Velocity,
    w_prev: f32,
    d_min: f32,
) -> RewardTerms {
    if collided || d_min < cfg.collision_range_m {
        return RewardTerms { r_c: cfg.collision, ..RewardTerms::default() };
    }
    let (v, w) = (vel.v, vel.w);
    let r_c = cfg.lambda_c * v * v * (v * w).cos();
    let (r_d, r_w) = penalties(cfg, w, w_prev, d_min);
    RewardTerms { r_c, r_d, r_w, r_g: 0.0 }
}

/// Eqs. (5) and (6): too close to an obstacle, and a swing of the angular velocity.
fn penalties(cfg: &RewardConfig, w: f32, w_prev: f32, d_min: f32) -> (f32, f32) {
    let r_d = if cfg.collision_range_m < d_min && d_min < cfg.near_range_m {
        cfg.lambda_d * cfg.near_range_m / d_min
    } else {
        0.0
    };
    let r_w = if w * w_prev < 0.0 { cfg.lambda_w * (w - w_prev).abs() } else { 0.0 };
    (r_d, r_w)
}

/// What the navigation reward of a step depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavStep {
    /// The step ended in a collision.
    pub collided: bool,
    /// The robot reached the goal.
    pub reached: bool,
    /// True angular velocity at `t`.
    pub w: f32,
    /// True angular velocity at `t − 1`.
    pub w_prev: f32,
    /// Smallest laser range, metres.
    pub d_min: f32,
    /// Metres the distance to the goal shrank in the step (`d_{t−1} − d_t`).
    pub progress_m: f32,
}

/// The navigation reward: `reward.collision` on a collision (as eq. 4); `nav.arrival` on
/// reaching the goal; otherwise `nav.progress · (d_{t−1} − d_t)` plus eqs. (5) and (6). A
/// step that both reaches the goal and collides counts as a collision.
pub fn nav_reward(cfg: &RewardConfig, nav: &NavConfig, s: NavStep) -> RewardTerms {
    let NavStep { collided, reached, w, w_prev, d_min, progress_m } = s;
    if collided || d_min < cfg.collision_range_m {
        return RewardTerms { r_c: cfg.collision, ..RewardTerms::default() };
    }
    if reached {
        return RewardTerms { r_g: nav.arrival, ..RewardTerms::default() };
    }
    let (r_d, r_w) = penalties(cfg, w, w_prev, d_min);
    RewardTerms { r_c: 0.0, r_d, r_w, r_g: nav.progress * progress_m }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(v: f32, w: f32, w_prev: f32, d_min: f32) -> RewardTerms {
        reward(&RewardConfig::default(), false, Velocity::new(v, w), w_prev, d_min)
    }

    #[test]
    fn eq4_forward_progress() {
        let t = r(0.5, 0.0, 0.0, 3.0);
        assert_eq!(t, RewardTerms { r_c: 0.5, r_d: 0.0, r_w: 0.0, r_g: 0.0 });
        let w = std::f32::consts::PI / 12.0;
        let t = r(0.5, w, w, 3.0);
        assert!((t.r_c - 2.0 * 0.25 * (0.5 * w).cos()).abs() < 1e-7);
        assert_eq!(r(0.0, 1.0, 1.0, 3.0).total(), 0.0);
    }

    #[test]
    fn eq4_collision() {
        let c = reward(&RewardConfig::default(), true, Velocity::new(0.5, 0.0), 0.0, 3.0);
        assert_eq!(c.total(), -10.0);
        assert_eq!(r(0.5, 0.0, 0.0, 0.19).total(), -10.0, "d_min < 0.2 is a collision");
    }

    #[test]
    fn eq5_too_close() {
        let t = r(0.0, 0.0, 0.0, 0.25);
        assert!((t.r_d - (-0.05 * 0.4 / 0.25)).abs() < 1e-7);
        assert_eq!(r(0.0, 0.0, 0.0, 0.4).r_d, 0.0, "open interval");
        assert_eq!(r(0.0, 0.0, 0.0, 0.2).r_d, 0.0 - 0.0, "0.2 is not < 0.2: no collision, no r_d");
    }

    #[test]
    fn eq6_swing() {
        let t = r(0.0, 0.5, -0.3, 3.0);
        assert!((t.r_w - (-0.05 * 0.8)).abs() < 1e-7);
        assert_eq!(r(0.0, 0.5, 0.3, 3.0).r_w, 0.0, "same sign");
        assert_eq!(r(0.0, 0.5, 0.0, 3.0).r_w, 0.0, "product zero");
    }

    #[test]
    fn navigation_rewards_arrival_progress_and_keeps_the_papers_penalties() {
        let (cfg, nav) = (RewardConfig::default(), NavConfig::default());
        let s = |collided, reached, w, w_prev, d_min, progress_m| NavStep {
            collided,
            reached,
            w,
            w_prev,
            d_min,
            progress_m,
        };
        let t = nav_reward(&cfg, &nav, s(false, true, 0.0, 0.0, 1.0, 0.1));
        assert_eq!(t.total(), nav.arrival);
        let t = nav_reward(&cfg, &nav, s(true, true, 0.0, 0.0, 1.0, 0.1));
        assert_eq!(t.total(), cfg.collision, "a collision at the goal is a collision");
        let t = nav_reward(&cfg, &nav, s(false, false, 0.5, -0.5, 0.3, 0.1));
        assert!((t.r_g - 0.25).abs() < 1e-6, "{t:?}");
        assert!(t.r_d < 0.0 && t.r_w < 0.0 && t.r_c == 0.0, "{t:?}");
        let back = nav_reward(&cfg, &nav, s(false, false, 0.0, 0.0, 1.0, -0.1));
        assert!(back.total() < 0.0, "moving away costs: {back:?}");
    }
}
