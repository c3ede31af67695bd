//! Pedestrians: cylinders walking their waypoints, deterministic under a seed.
//!
//! Each walks towards its next waypoint at its speed; at the last waypoint it turns back
//! (or, with `loop`, goes on to the first). If another pedestrian blocks its way it waits,
//! and after `wait_s` turns back. The robot blocks a walker the same way when the simulator
//! says walkers yield to it (`pedestrian_yield_m`, the default): as a person would, a walker
//! does not walk into a robot that stands in its way nor run it down from behind, so a
//! pedestrian collision is one the robot drove into. With yielding off (the simulator before
//! 2026-12-06) walkers ignore the robot and walking into it is a collision all the same
//! (SPEC §2). Pedestrians are updated in index order, so results are deterministic.

use mdrlat_core::Rng;
use mdrlat_geom::{Cylinder, Prism, Shape, Vec2};
use mdrlat_world::PedestrianSpec;

/// The moving state of one pedestrian.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PedestrianState {
    /// Centre, world frame.
    pub position: Vec2,
    /// Index of the waypoint walked to.
    pub target: usize,
    /// +1 walking forward through the waypoints, −1 backward.
    pub direction: i32,
    /// Time spent blocked so far, seconds.
    pub waited_s: f32,
}

/// Places every pedestrian at a random point of its path, walking a random way.
pub fn reset(specs: &[PedestrianSpec], rng: &mut Rng) -> Vec<PedestrianState> {
    specs
        .iter()
        .map(|spec| {
            let n = spec.waypoints.len();
            let segments = if spec.looped { n } else { n - 1 };
            let seg = rng.below(segments);
            let (a, b) = (spec.waypoints[seg], spec.waypoints[(seg + 1) % n]);
            let f = rng.uniform() as f32;
            let forward = spec.looped || rng.below(2) == 0;
            let (target, direction) = if forward { ((seg + 1) % n, 1) } else { (seg, -1) };
            PedestrianState { position: a + (b - a) * f, target, direction, waited_s: 0.0 }
        })
        .collect()
}

/// The waypoint after `target` in the walking direction: around the loop (either way) for
/// looped paths; ping-pong at the ends otherwise.
fn next_target(spec: &PedestrianSpec, st: &mut PedestrianState) {
    let n = spec.waypoints.len() as i32;
    if spec.looped {
        st.target = (st.target as i32 + st.direction).rem_euclid(n) as usize;
        return;
    }
    let next = st.target as i32 + st.direction;
    if next < 0 || next >= n {
        st.direction = -st.direction;
    }
    st.target = (st.target as i32 + st.direction) as usize;
}

/// Reverses the walking direction: the new target is the waypoint just passed.
fn turn_back(spec: &PedestrianSpec, st: &mut PedestrianState) {
    let n = spec.waypoints.len() as i32;
    st.direction = -st.direction;
    st.target = if spec.looped {
        (st.target as i32 + st.direction).rem_euclid(n) as usize
    } else {
        (st.target as i32 + st.direction).clamp(0, n - 1) as usize
    };
}

/// A disc walkers keep out of: they do not step closer to its centre than its radius plus
/// their own (the robot's footprint plus the personal space walkers keep from it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keepout {
    /// Centre, world frame.
    pub center: Vec2,
    /// Radius, metres.
    pub radius: f32,
}

/// Moves every pedestrian by `dt` seconds; a walker whose next step would come closer to
/// another walker, or into `keepout` (the robot, when walkers yield to it), waits instead.
pub fn advance(
    specs: &[PedestrianSpec],
    states: &mut [PedestrianState],
    keepout: Option<Keepout>,
    dt: f32,
) {
    for i in 0..states.len() {
        let spec = &specs[i];
        let mut st = states[i];
        let mut budget = spec.speed * dt;
        // Walk through as many waypoints as this step reaches.
        for _ in 0..spec.waypoints.len() + 1 {
            let goal = spec.waypoints[st.target];
            let to = goal - st.position;
            let dist = to.length();
            let step = budget.min(dist);
            let next = if dist > 0.0 { st.position + to * (step / dist) } else { st.position };
            // Blocked by a disc: the step ends inside it and closer than before.
            let blocks = |center: Vec2, radius: f32| {
                let d_next = (next - center).length();
                d_next < spec.radius + radius && d_next < (st.position - center).length()
            };
            let blocked = states
                .iter()
                .enumerate()
                .any(|(k, o)| k != i && blocks(o.position, specs[k].radius))
                || keepout.is_some_and(|k| blocks(k.center, k.radius));
            if blocked {
                st.waited_s += dt;
                if st.waited_s >= spec.wait_s {
                    st.waited_s = 0.0;
                    turn_back(spec, &mut st);
                }
                break;
            }
            st.waited_s = 0.0;
            st.position = next;
            budget -= step;
            if step < dist || budget <= 0.0 {
                break;
            }
            let step_back = st;
            next_target(spec, &mut st);
            if st.target == step_back.target {
                break;
            }
        }
        states[i] = st;
    }
}

/// Writes each pedestrian as a cylinder prism into `out` (reusing its storage).
pub fn write_prisms(specs: &[PedestrianSpec], states: &[PedestrianState], out: &mut Vec<Prism>) {
    out.clear();
    out.extend(specs.iter().zip(states).map(|(spec, st)| {
        Prism::new(
            Shape::Cylinder(Cylinder { center: st.position, radius: spec.radius }),
            0.0,
            spec.height,
        )
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walker(looped: bool) -> PedestrianSpec {
        PedestrianSpec {
            waypoints: vec![Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0), Vec2::new(2.0, 2.0)],
            speed: 1.0,
            radius: 0.25,
            height: 1.7,
            looped,
            wait_s: 1.0,
        }
    }

    #[test]
    fn walks_at_speed_and_turns_back_at_the_end() {
        let specs = [walker(false)];
        let mut st =
            [PedestrianState { position: Vec2::ZERO, target: 1, direction: 1, waited_s: 0.0 }];
        advance(&specs, &mut st, None, 0.5);
        assert!((st[0].position - Vec2::new(0.5, 0.0)).length() < 1e-6);
        advance(&specs, &mut st, None, 2.0); // 2 m: corner at (2,0), then 0.5 m up
        assert!((st[0].position - Vec2::new(2.0, 0.5)).length() < 1e-5, "{:?}", st[0]);
        advance(&specs, &mut st, None, 2.0); // 1.5 m to the end, 0.5 m back
        assert!((st[0].position - Vec2::new(2.0, 1.5)).length() < 1e-5, "{:?}", st[0]);
        assert_eq!(st[0].direction, -1);
    }

    #[test]
    fn loops_when_asked() {
        let specs = [walker(true)];
        let mut st = [PedestrianState {
            position: Vec2::new(2.0, 2.0),
            target: 0,
            direction: 1,
            waited_s: 0.0,
        }];
        let diag = 8f32.sqrt();
        advance(&specs, &mut st, None, diag + 0.5);
        assert!((st[0].position - Vec2::new(0.5, 0.0)).length() < 1e-4, "{:?}", st[0]);
    }

    #[test]
    fn blocked_walkers_wait_then_turn_back() {
        let spec = walker(false);
        let specs = [spec.clone(), spec];
        let mut st = [
            PedestrianState {
                position: Vec2::new(0.5, 0.0),
                target: 1,
                direction: 1,
                waited_s: 0.0,
            },
            PedestrianState {
                position: Vec2::new(1.0, 0.0),
                target: 0,
                direction: -1,
                waited_s: 0.0,
            },
        ];
        advance(&specs, &mut st, None, 0.2);
        assert_eq!(st[0].position, Vec2::new(0.5, 0.0), "blocked: waits");
        for _ in 0..5 {
            advance(&specs, &mut st, None, 0.2);
        }
        assert_eq!(st[0].direction, -1, "turned back after waiting");
    }

    #[test]
    fn a_looped_walker_that_turns_back_walks_its_loop_backwards() {
        let square = PedestrianSpec {
            waypoints: vec![
                Vec2::new(0.0, 0.0),
                Vec2::new(2.0, 0.0),
                Vec2::new(2.0, 2.0),
                Vec2::new(0.0, 2.0),
            ],
            speed: 1.0,
            radius: 0.25,
            height: 1.7,
            looped: true,
            wait_s: 0.2,
        };
        let mut blocker = square.clone();
        blocker.speed = 1e-3;
        let specs = [square, blocker];
        let mut st = [
            PedestrianState {
                position: Vec2::new(1.0, 0.0),
                target: 1,
                direction: 1,
                waited_s: 0.0,
            },
            PedestrianState {
                position: Vec2::new(1.45, 0.0),
                target: 0,
                direction: -1,
                waited_s: 0.0,
            },
        ];
        for _ in 0..3 {
            advance(&specs, &mut st, None, 0.1); // blocked: waits, then turns back
        }
        assert_eq!((st[0].direction, st[0].target), (-1, 0));
        // Walking backwards it passes waypoint 0 and goes on to waypoint 3, not back to 1.
        for _ in 0..15 {
            advance(&specs, &mut st, None, 0.1);
        }
        assert_eq!(st[0].target, 3, "{:?}", st[0]);
        assert!(st[0].position.x.abs() < 1e-4 && st[0].position.y > 0.4, "{:?}", st[0]);
    }

    #[test]
    fn walkers_yield_to_the_robot_in_their_way_and_behind_it() {
        let specs = [walker(false)];
        let start =
            PedestrianState { position: Vec2::ZERO, target: 1, direction: 1, waited_s: 0.0 };
        // A robot standing on the walker's path at x = 1.2: the walker stops short of it, waits
        // `wait_s`, then turns back, and never comes within the keep-out disc.
        let robot = Keepout { center: Vec2::new(1.2, 0.0), radius: 0.177 + 0.3 };
        let mut st = [start];
        let mut closest = f32::INFINITY;
        for k in 1..=40 {
            advance(&specs, &mut st, Some(robot), 0.1);
            closest = closest.min((st[0].position - robot.center).length());
            if k == 4 {
                assert!((st[0].position.x - 0.4).abs() < 1e-5, "{:?}", st[0]);
            }
            if (5..14).contains(&k) {
                assert_eq!(st[0].position.x, 0.4, "waits at step {k}");
            }
            if k == 16 {
                assert_eq!(st[0].direction, -1, "turned back after waiting");
            }
        }
        assert!(closest >= 0.25 + robot.radius - 1e-5, "came within {closest}");
        // Without yielding the same walker walks through the robot's place.
        let mut st = [start];
        for _ in 0..15 {
            advance(&specs, &mut st, None, 0.1);
        }
        assert!(st[0].position.x > 1.4, "{:?}", st[0]);
        // A robot ahead and moving away is not in the way of a walker that stays clear.
        let far = Keepout { center: Vec2::new(1.9, 0.0), radius: 0.477 };
        let mut st = [start];
        advance(&specs, &mut st, Some(far), 0.5);
        assert!((st[0].position.x - 0.5).abs() < 1e-6, "{:?}", st[0]);
    }

    #[test]
    fn reset_is_seeded() {
        let specs = vec![walker(false); 5];
        let a = reset(&specs, &mut Rng::seed_from_u64(3));
        let b = reset(&specs, &mut Rng::seed_from_u64(3));
        assert_eq!(a, b);
        // The seed decides: another one puts the walkers elsewhere, and the five walkers of
        // one reset are not all in one place (each draws its own start).
        let c = reset(&specs, &mut Rng::seed_from_u64(4));
        assert_ne!(a, c);
        assert!(a.iter().any(|w| w.position != a[0].position), "{a:?}");
        // Every start lies on its path, between two consecutive waypoints.
        for w in a.iter().chain(&c) {
            let on_path = specs[0].waypoints.windows(2).any(|p| {
                let (d, e) = (p[1] - p[0], w.position - p[0]);
                (d.x * e.y - d.y * e.x).abs() < 1e-4
                    && e.dot(d) >= -1e-6
                    && e.dot(d) <= d.dot(d) + 1e-6
            });
            assert!(on_path, "{w:?} is off its path");
        }
    }
}
