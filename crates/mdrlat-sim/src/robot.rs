//! Differential-drive kinematics with acceleration limits.

use crate::config::RobotConfig;
use mdrlat_core::Velocity;
use mdrlat_geom::Pose2;

/// Pose and true velocity of the robot.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct RobotState {
    /// Pose in the world frame.
    pub pose: Pose2,
    /// True (odometry) velocity.
    pub velocity: Velocity,
}

impl RobotState {
    /// Advances by `dt` seconds towards the command `cmd`: each velocity moves towards its
    /// command by at most its acceleration limit times `dt` (so odometry lags commands), then
    /// the pose follows the exact arc of the new velocities.
    pub fn advance(&mut self, cmd: Velocity, cfg: &RobotConfig, dt: f32) {
        let dv = cfg.max_linear_accel * dt;
        let dw = cfg.max_angular_accel * dt;
        let v = self.velocity.v + (cmd.v - self.velocity.v).clamp(-dv, dv);
        let w = self.velocity.w + (cmd.w - self.velocity.w).clamp(-dw, dw);
        self.velocity = Velocity::new(v, w);
        let p = &mut self.pose;
        if w.abs() < 1e-6 {
            let (s, c) = p.yaw.sin_cos();
            p.x += v * dt * c;
            p.y += v * dt * s;
        } else {
            let yaw1 = p.yaw + w * dt;
            p.x += v / w * (yaw1.sin() - p.yaw.sin());
            p.y -= v / w * (yaw1.cos() - p.yaw.cos());
            p.yaw = mdrlat_geom::math::wrap_angle(yaw1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn acceleration_limits_make_odometry_lag() {
        let cfg = RobotConfig::default();
        let mut s = RobotState::default();
        s.advance(Velocity::new(0.5, 1.0), &cfg, 0.2);
        assert!((s.velocity.v - 0.2).abs() < 1e-6, "1.0 m/s² for 0.2 s");
        assert!((s.velocity.w - 0.4).abs() < 1e-6, "2.0 rad/s² for 0.2 s");
        for _ in 0..3 {
            s.advance(Velocity::new(0.5, 1.0), &cfg, 0.2);
        }
        assert_eq!(s.velocity, Velocity::new(0.5, 1.0));
    }

    #[test]
    fn arcs_are_exact() {
        // A full circle at v = 0.5, w = 0.5 has radius 1 and returns to the start.
        let cfg =
            RobotConfig { max_linear_accel: 100.0, max_angular_accel: 100.0, ..Default::default() };
        let mut s = RobotState { velocity: Velocity::new(0.5, 0.5), ..Default::default() };
        let steps = 1000;
        let dt = std::f32::consts::TAU / 0.5 / steps as f32;
        let mut max_y = 0.0f32;
        for _ in 0..steps {
            s.advance(Velocity::new(0.5, 0.5), &cfg, dt);
            max_y = max_y.max(s.pose.y);
        }
        assert!(s.pose.x.abs() < 1e-3 && s.pose.y.abs() < 1e-3, "{:?}", s.pose);
        assert!((max_y - 2.0).abs() < 1e-3);
    }
}
