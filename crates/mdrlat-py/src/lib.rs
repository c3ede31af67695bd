//! `mdrlat._core`: the simulator for Python. One class, [`Env`], over the Rust
//! [`mdrlat_sim::Env`]: observations in metres as numpy arrays (the frame stacks oldest
//! first, as the networks read them), Gymnasium's `terminated`/`truncated` kept apart, the
//! top view with the depth image as an RGB array. The Gymnasium classes are Python
//! (`python/mdrlat/`); this module only moves data. Every failure is a Python exception
//! naming what failed; nothing panics across the boundary.

use mdrlat_core::{
    DEPTH_COLS, DEPTH_LEN, DEPTH_ROWS, FRAME_STACK, GOAL_DIM, LASER_BEAMS, ODOM_HISTORY,
};
use mdrlat_geom::{Pose2, Vec2};
use mdrlat_sim::config::Task;
use mdrlat_sim::{Collision, Observation, SimConfig};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray3, PyReadonlyArray1, PyReadwriteArray1, PyReadwriteArray2,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The simulator's name for a collision (`bumper`, `pedestrian`, `laser`), as `episodes.csv`
/// writes it.
fn collision_name(c: &Collision) -> &'static str {
    mdrlat_eval::protocol::collision_kind(c)
}

fn sim_error(e: mdrlat_sim::SimError) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

/// The world `spec` names and the settings `config_json` holds, checked: a `ValueError`
/// naming the file, the key or the value otherwise.
fn load(spec: &str, config_json: &str) -> PyResult<(mdrlat_world::World, SimConfig)> {
    let config: SimConfig = serde_json::from_str(config_json)
        .map_err(|e| PyValueError::new_err(format!("simulator settings: {e}")))?;
    config.validate().map_err(|e| PyValueError::new_err(format!("simulator settings: {e}")))?;
    let world = mdrlat_world::load(spec).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((world, config))
}

/// One simulated robot in one world (paper section 2.1; SPEC §2).
#[pyclass(module = "mdrlat._core")]
pub struct Env {
    env: mdrlat_sim::Env,
    /// The episode's positions, for the picture.
    trail: Vec<Vec2>,
    /// How the last step ended, for the picture.
    collided: bool,
    /// The world as given (a name or a path), for pickling.
    spec: String,
    /// The settings as given (JSON), for pickling.
    config_json: String,
}

/// An observation as a dict of numpy arrays, fresh ones (a single-env user may keep them):
/// the stacks copied frame by frame into new vectors
/// ([`mdrlat_core::FrameStack::to_stacked_vec`]), with plain stores (the arrays are read
/// soon, and new memory is better not zeroed first: zeroing and then copying took 37 % of a
/// one-env step on an AMD EPYC Zen 4 VM).
fn observation_dict<'py>(py: Python<'py>, obs: &Observation) -> PyResult<Bound<'py, PyDict>> {
    let goal_len = if obs.goal.is_some() { GOAL_DIM } else { 0 };
    let (mut odom, mut goal) = (vec![0.0f32; 2 * ODOM_HISTORY], vec![0.0f32; goal_len]);
    write_vectors(obs, &mut odom, &mut goal);
    let d = PyDict::new(py);
    let laser = Array2::from_shape_vec((FRAME_STACK, LASER_BEAMS), obs.laser.to_stacked_vec())
        .map_err(|e| PyRuntimeError::new_err(format!("laser stack: {e}")))?;
    let depth =
        Array3::from_shape_vec((FRAME_STACK, DEPTH_ROWS, DEPTH_COLS), obs.depth.to_stacked_vec())
            .map_err(|e| PyRuntimeError::new_err(format!("depth stack: {e}")))?;
    d.set_item("laser", laser.into_pyarray(py))?;
    d.set_item("depth", depth.into_pyarray(py))?;
    d.set_item("odom", Array1::from_vec(odom).into_pyarray(py))?;
    if obs.goal.is_some() {
        d.set_item("goal", Array1::from_vec(goal).into_pyarray(py))?;
    }
    Ok(d)
}

/// The odometry history `(v, w)` oldest first into `odom` (6 values), and the goal into
/// `goal` unless that is empty (no navigation task).
fn write_vectors(obs: &Observation, odom: &mut [f32], goal: &mut [f32]) {
    for (k, v) in obs.odom.iter().enumerate() {
        (odom[2 * k], odom[2 * k + 1]) = (v.v, v.w);
    }
    if let (Some(g), false) = (obs.goal, goal.is_empty()) {
        goal.copy_from_slice(&g);
    }
}

/// A step's `info` dict entries: velocity, `d_min`, collision kind, goal reached.
fn step_info(d: &Bound<'_, PyDict>, s: &mdrlat_sim::StepInfo) -> PyResult<()> {
    d.set_item("velocity", (s.velocity.v, s.velocity.w))?;
    d.set_item("d_min", s.d_min)?;
    d.set_item("collision", s.collision.as_ref().map(collision_name))?;
    d.set_item("reached_goal", s.reached_goal)
}

impl Env {
    /// The current observation as a dict of numpy arrays.
    fn observation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        observation_dict(py, self.env.observation())
    }

    /// The step's `info` dict: pose, velocity, `d_min`, collision kind, goal reached.
    fn info<'py>(
        &self,
        py: Python<'py>,
        step: Option<&mdrlat_sim::StepInfo>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let pose = self.env.pose();
        d.set_item("pose", (pose.x, pose.y, pose.yaw.to_degrees()))?;
        d.set_item("step", self.env.episode_steps())?;
        if let Some(goal) = self.env.goal() {
            d.set_item("goal", (goal.x, goal.y))?;
        }
        if let Some(s) = step {
            step_info(&d, s)?;
        }
        Ok(d)
    }
}

#[pymethods]
impl Env {
    /// An environment in `world` (a built-in name, a `.toml` world file or a map_server
    /// `.yaml`) with the simulator settings `config_json` (a JSON object of `[sim]` keys;
    /// the defaults for everything it leaves out).
    #[new]
    #[pyo3(signature = (world, config_json = "{}"))]
    fn new(world: &str, config_json: &str) -> PyResult<Self> {
        let (loaded, config) = load(world, config_json)?;
        let env = mdrlat_sim::Env::from_world(loaded, config)
            .map_err(|e| PyValueError::new_err(format!("world '{world}': {e}")))?;
        let trail = vec![env.pose().position()];
        Ok(Self {
            env,
            trail,
            collided: false,
            spec: world.to_string(),
            config_json: config_json.to_string(),
        })
    }

    /// Starts an episode: from the seed's start pose (and goal, navigation), or at `pose`
    /// `(x, y, yaw_deg)`. Returns `(observation, info)`.
    #[pyo3(signature = (seed = None, pose = None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: Option<u64>,
        pose: Option<(f32, f32, f32)>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
        let pose = pose.map(|(x, y, yaw)| Pose2::new(x, y, yaw.to_radians()));
        if let Some(p) = pose
            && !(p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite())
        {
            return Err(PyValueError::new_err(format!("pose {p:?}: not finite")));
        }
        self.env.reset_with(seed, pose).map_err(sim_error)?;
        self.trail.clear();
        self.trail.push(self.env.pose().position());
        self.collided = false;
        Ok((self.observation(py)?, self.info(py, None)?))
    }

    /// One control period with Table 1 action `action` (0–9). Returns `(observation,
    /// reward, terminated, truncated, info)`; `terminated` is a collision (or, navigating,
    /// the goal reached), `truncated` the time limit.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        action: i64,
    ) -> PyResult<(Bound<'py, PyDict>, f32, bool, bool, Bound<'py, PyDict>)> {
        let a = usize::try_from(action)
            .ok()
            .and_then(mdrlat_core::Action::new)
            .ok_or_else(|| PyValueError::new_err(format!("action {action}: expected 0 to 9")))?;
        let s = self.env.step(a).map_err(sim_error)?;
        let (reward, terminated, truncated, info) = (s.reward, s.terminated, s.truncated, s.info);
        self.collided = info.collision.is_some();
        self.trail.push(self.env.pose().position());
        Ok((self.observation(py)?, reward, terminated, truncated, self.info(py, Some(&info))?))
    }

    /// The top view (robot, laser rays, pedestrians, the episode's trail, the goal) with
    /// the current depth image beside it, as a `(height, width, 3)` uint8 array.
    fn render<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let scale = mdrlat_eval::figures::px_per_m(self.env.world(), 480.0);
        let caption = format!("{} step {}", self.env.world().name, self.env.episode_steps());
        let image =
            mdrlat_eval::figures::snapshot(&self.env, &self.trail, &caption, self.collided, scale);
        let (w, h) = (image.width as usize, image.height as usize);
        let rgb: Vec<u8> = image.rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let array = Array3::from_shape_vec((h, w, 3), rgb)
            .map_err(|e| PyRuntimeError::new_err(format!("picture: {e}")))?;
        Ok(array.into_pyarray(py))
    }

    /// The world's name.
    #[getter]
    fn world_name(&self) -> String {
        self.env.world().name.clone()
    }

    /// The world as given to the constructor.
    #[getter]
    fn spec(&self) -> String {
        self.spec.clone()
    }

    /// The settings as given to the constructor (JSON).
    #[getter]
    fn config_json(&self) -> String {
        self.config_json.clone()
    }

    /// The task: `avoid` or `nav`.
    #[getter]
    fn task(&self) -> &'static str {
        self.env.config().task.name()
    }

    /// Steps after which an episode is truncated.
    #[getter]
    fn max_episode_steps(&self) -> u32 {
        self.env.config().max_episode_steps
    }

    /// The length of the world's bounds' diagonal, metres (no goal is farther).
    #[getter]
    fn world_diagonal(&self) -> f32 {
        self.env.world().bounds.size().length()
    }

    /// The laser's and the depth camera's largest range, metres (the observation bounds).
    #[getter]
    fn max_ranges(&self) -> (f32, f32) {
        let c = self.env.config();
        (c.laser.max_range_m, c.depth.max_range_m)
    }
}

/// Frames of each environment's window in the vector env's laser and depth buffers: an
/// observation is a view of 4 consecutive frames, which slides on by one frame a step, so
/// a step writes one new frame per environment instead of moving the whole stack (a full
/// stack only after a reset, and when the window reaches the end: every
/// `WINDOW_FRAMES − FRAME_STACK` steps).
const WINDOW_FRAMES: usize = 32;

/// One observation's place in numpy buffers: `laser` and `depth` a whole stack (`frames`
/// = 4) or an environment's window buffer (`frames` = [`WINDOW_FRAMES`]), `odom`, and
/// `goal` (empty without the navigation task).
struct ObsSlot<'a> {
    laser: &'a mut [f32],
    depth: &'a mut [f32],
    odom: &'a mut [f32],
    goal: &'a mut [f32],
}

impl ObsSlot<'_> {
    /// Writes `obs` (metres, stacks oldest first) with its stacks starting at frame
    /// `offset`: the whole stacks where `full`, else only the newest frames (the other
    /// three are there from the step before, one frame earlier).
    fn write(&mut self, obs: &Observation, offset: usize, full: bool) {
        for (stack, buf) in [(&obs.laser, &mut *self.laser), (&obs.depth, &mut *self.depth)] {
            let n = stack.frame_len();
            if full {
                stack.write_stacked(&mut buf[offset * n..(offset + FRAME_STACK) * n], stream_copy);
            } else {
                let newest = offset + FRAME_STACK - 1;
                stream_copy(stack.latest(), &mut buf[newest * n..(newest + 1) * n]);
            }
        }
        stream_fence();
        write_vectors(obs, self.odom, self.goal);
    }
}

/// `to.copy_from_slice(from)` with non-temporal stores on x86-64: the frames go to the
/// window buffers (`N × 32` frames, 10 MB for 4 environments) at a place last written 28
/// steps before, long out of this core's caches, where ordinary stores first read every
/// line in (a 80 KB depth frame copied at ~7 GB/s, 15 % of a `VectorEnv.step` on one AMD
/// EPYC Zen 4 VM); streaming stores write the lines without reading them. Followed by
/// [`stream_fence`] before anything else may read the buffer.
///
/// # Panics
/// If the lengths differ.
fn stream_copy(from: &[f32], to: &mut [f32]) {
    assert_eq!(from.len(), to.len(), "stream_copy: lengths differ");
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_stream_ps};
        // Plain stores up to the first 16-byte boundary of `to` (floats are 4-byte aligned).
        let head = to.as_ptr().align_offset(16).min(to.len());
        to[..head].copy_from_slice(&from[..head]);
        let (from, to) = (&from[head..], &mut to[head..]);
        let body = to.len() / 4 * 4;
        for (f, t) in from[..body].chunks_exact(4).zip(to[..body].chunks_exact_mut(4)) {
            // SAFETY: SSE is part of x86-64; `f` holds 4 floats and `t` 4 floats starting
            // at a 16-byte boundary (every chunk after the head is 16 bytes on from it).
            #[allow(unsafe_code)]
            unsafe {
                _mm_stream_ps(t.as_mut_ptr(), _mm_loadu_ps(f.as_ptr()));
            }
        }
        to[body..].copy_from_slice(&from[body..]);
    }
    #[cfg(not(target_arch = "x86_64"))]
    to.copy_from_slice(from);
}

/// Orders the streaming stores of [`stream_copy`] before every later store (the worker's
/// "done" that hands the buffers back to Python): they are weakly ordered otherwise.
fn stream_fence() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of x86-64; a fence has no other effect.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm_sfence();
    }
}

/// An environment's places in the buffers: its current observation's window and its
/// last episode's final observation.
struct EnvSlot<'a> {
    now: ObsSlot<'a>,
    last: ObsSlot<'a>,
}

/// Numpy buffers a [`VecEnv`] writes into (float32, C order): the current observations,
/// with the frame windows `laser` `(N, 32, 512)` and `depth` `(N, 32, 128, 160)` (see
/// [`WINDOW_FRAMES`]), `odom` `(N, 6)`, `goal` `(N, 3)` or `(0, 3)`; and the final
/// observations of ended episodes, `final_laser` `(N, 4, 512)`, `final_depth` `(N, 4, 128,
/// 160)`, `final_odom`, `final_goal`.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct Buffers<'py> {
    laser: numpy::PyReadwriteArrayDyn<'py, f32>,
    depth: numpy::PyReadwriteArrayDyn<'py, f32>,
    odom: PyReadwriteArray2<'py, f32>,
    goal: PyReadwriteArray2<'py, f32>,
    final_laser: numpy::PyReadwriteArrayDyn<'py, f32>,
    final_depth: numpy::PyReadwriteArrayDyn<'py, f32>,
    final_odom: PyReadwriteArray2<'py, f32>,
    final_goal: PyReadwriteArray2<'py, f32>,
}

/// A C-order buffer as a slice of `n` rows of `row` values each.
fn rows<'a, D: numpy::ndarray::Dimension>(
    name: &str,
    a: &'a mut numpy::PyReadwriteArray<'_, f32, D>,
    n: usize,
    row: usize,
) -> PyResult<std::slice::ChunksExactMut<'a, f32>> {
    if a.len() != n * row {
        return Err(PyValueError::new_err(format!(
            "buffer '{name}' holds {} values, {n} environments need {}",
            a.len(),
            n * row
        )));
    }
    if !a.is_c_contiguous() {
        return Err(PyValueError::new_err(format!("buffer '{name}' is not C-contiguous")));
    }
    let s = a.as_slice_mut().map_err(|e| PyValueError::new_err(format!("buffer '{name}': {e}")))?;
    // `chunks_exact_mut(0)` panics; an empty buffer (no goals) has no rows.
    Ok(s.chunks_exact_mut(row.max(1)))
}

/// Every environment's slots in `b`, checked against `n` environments (and `nav`).
fn env_slots<'a>(b: &'a mut Buffers<'_>, n: usize, nav: bool) -> PyResult<Vec<EnvSlot<'a>>> {
    let (laser, depth, odom) = (LASER_BEAMS, DEPTH_LEN, 2 * ODOM_HISTORY);
    let goal = if nav { GOAL_DIM } else { 0 };
    let mut now_l = rows("laser", &mut b.laser, n, WINDOW_FRAMES * laser)?;
    let mut now_d = rows("depth", &mut b.depth, n, WINDOW_FRAMES * depth)?;
    let mut now_o = rows("odom", &mut b.odom, n, odom)?;
    let mut now_g = rows("goal", &mut b.goal, n, goal)?;
    let mut last_l = rows("final_laser", &mut b.final_laser, n, FRAME_STACK * laser)?;
    let mut last_d = rows("final_depth", &mut b.final_depth, n, FRAME_STACK * depth)?;
    let mut last_o = rows("final_odom", &mut b.final_odom, n, odom)?;
    let mut last_g = rows("final_goal", &mut b.final_goal, n, goal)?;
    // A goal-less buffer has no rows: its slots get empty goals.
    let mut next = || -> Option<EnvSlot<'a>> {
        Some(EnvSlot {
            now: ObsSlot {
                laser: now_l.next()?,
                depth: now_d.next()?,
                odom: now_o.next()?,
                goal: now_g.next().unwrap_or_default(),
            },
            last: ObsSlot {
                laser: last_l.next()?,
                depth: last_d.next()?,
                odom: last_o.next()?,
                goal: last_g.next().unwrap_or_default(),
            },
        })
    };
    (0..n).map(|_| next().ok_or_else(|| PyRuntimeError::new_err("buffers: too few rows"))).collect()
}

/// N environments stepped in parallel on all cores by the Rust `VecEnv`, the GIL
/// released, writing into numpy buffers the caller keeps (no arrays made per step): each
/// environment's thread writes its observations right after its step. Finished episodes
/// restart at once (Gymnasium's same-step autoreset); their final observations go to the
/// `final_*` buffers.
#[pyclass(module = "mdrlat._core")]
pub struct VecEnv {
    venv: mdrlat_sim::VecEnv,
    nav: bool,
    actions: Vec<mdrlat_core::Action>,
    /// Where the observations' 4-frame windows start in the laser and depth buffers.
    offset: usize,
}

#[pymethods]
impl VecEnv {
    /// `num_envs` environments in `world` with the settings `config_json` (as [`Env`]),
    /// on `threads` threads (0: every core).
    #[new]
    #[pyo3(signature = (world, config_json = "{}", num_envs = 1, threads = 0))]
    fn new(world: &str, config_json: &str, num_envs: usize, threads: usize) -> PyResult<Self> {
        if num_envs == 0 || num_envs > 4096 {
            return Err(PyValueError::new_err(format!("num_envs {num_envs}: expected 1 to 4096")));
        }
        let (loaded, config) = load(world, config_json)?;
        let nav = config.task == Task::Nav;
        let scene =
            std::sync::Arc::new(mdrlat_sim::StaticScene::new(std::sync::Arc::new(loaded), &config));
        let venv = mdrlat_sim::VecEnv::new(scene, config, num_envs, threads)
            .map_err(|e| PyValueError::new_err(format!("world '{world}': {e}")))?;
        Ok(Self { venv, nav, actions: Vec::with_capacity(num_envs), offset: 0 })
    }

    /// Starts an episode in every environment: environment `i` with `seeds[i]` (`None`:
    /// its stream goes on), exactly as `Env.reset(seed=seeds[i])`; writes the observations
    /// into `buffers` (windows at frame 0). Returns each environment's pose `(x, y,
    /// yaw_deg)`.
    fn reset(
        &mut self,
        py: Python<'_>,
        seeds: Vec<Option<u64>>,
        mut buffers: Buffers<'_>,
    ) -> PyResult<Vec<(f32, f32, f32)>> {
        let n = self.venv.len();
        if seeds.len() != n {
            return Err(PyValueError::new_err(format!(
                "{} seeds for {n} environments",
                seeds.len()
            )));
        }
        let mut slots = env_slots(&mut buffers, n, self.nav)?;
        let venv = &mut self.venv;
        py.detach(|| -> Result<(), mdrlat_sim::SimError> {
            for (i, seed) in seeds.iter().enumerate() {
                venv.reset_env(i, *seed, None)?;
            }
            Ok(())
        })
        .map_err(sim_error)?;
        self.offset = 0;
        for (i, slot) in slots.iter_mut().enumerate() {
            slot.now.write(&self.venv.observation(i), 0, true);
        }
        Ok((0..n)
            .map(|i| {
                let p = self.venv.env(i).pose();
                (p.x, p.y, p.yaw.to_degrees())
            })
            .collect())
    }

    /// One step of every environment with `actions[i]` (0–9): writes the observations
    /// (after any autoreset) into `buffers`, the rewards and flags into `rewards`,
    /// `terminated`, `truncated`, and each step's `d_min`. The buffers are written while
    /// the step runs, without the GIL: do not read them from another thread meanwhile.
    /// Returns the frame at which the observations' windows now start (frames `offset..offset
    /// + 4` of the laser and depth buffers; the last step's windows are unchanged until the
    /// buffers wrap) and, for every environment whose episode ended, `(i, final_info)` (its
    /// final observation is row `i` of the `final_*` buffers).
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArray1<'py, i64>,
        mut buffers: Buffers<'py>,
        mut rewards: PyReadwriteArray1<'py, f32>,
        mut terminated: PyReadwriteArray1<'py, bool>,
        mut truncated: PyReadwriteArray1<'py, bool>,
        mut d_min: PyReadwriteArray1<'py, f32>,
    ) -> PyResult<(usize, Vec<(usize, Bound<'py, PyDict>)>)> {
        let n = self.venv.len();
        let acts =
            actions.as_slice().map_err(|e| PyValueError::new_err(format!("actions: {e}")))?;
        if acts.len() != n {
            return Err(PyValueError::new_err(format!(
                "{} actions for {n} environments",
                acts.len()
            )));
        }
        self.actions.clear();
        for (i, &a) in acts.iter().enumerate() {
            let action =
                usize::try_from(a).ok().and_then(mdrlat_core::Action::new).ok_or_else(|| {
                    PyValueError::new_err(format!("actions[{i}] = {a}: expected 0 to 9"))
                })?;
            self.actions.push(action);
        }
        for (name, len) in [
            ("rewards", rewards.len()),
            ("terminated", terminated.len()),
            ("truncated", truncated.len()),
            ("d_min", d_min.len()),
        ] {
            if len != n {
                return Err(PyValueError::new_err(format!(
                    "buffer '{name}' holds {len} values, expected {n}"
                )));
            }
        }
        let c = |e: numpy::AsSliceError| PyValueError::new_err(format!("buffers: {e}"));
        let mut slots = env_slots(&mut buffers, n, self.nav)?;
        let (rw, te, tr, dm) = (
            rewards.as_slice_mut().map_err(c)?,
            terminated.as_slice_mut().map_err(c)?,
            truncated.as_slice_mut().map_err(c)?,
            d_min.as_slice_mut().map_err(c)?,
        );
        // The windows slide on by a frame, or start again from the front of the buffers.
        let wrap = self.offset + 1 + FRAME_STACK > WINDOW_FRAMES;
        let offset = if wrap { 0 } else { self.offset + 1 };
        let write = move |slot: &mut EnvSlot<'_>,
                          _: &mdrlat_sim::VecStep,
                          last: Option<&Observation>,
                          now: &Observation| {
            if let Some(last) = last {
                slot.last.write(last, 0, true);
            }
            slot.now.write(now, offset, wrap || last.is_some());
        };
        let (venv, actions) = (&mut self.venv, &self.actions);
        let steps = py
            .detach(|| venv.step_into(actions, &mut slots, &write).map(<[_]>::to_vec))
            .map_err(sim_error)?;
        self.offset = offset;
        let mut ended = Vec::new();
        for (i, s) in steps.iter().enumerate() {
            (rw[i], te[i], tr[i], dm[i]) = (s.reward, s.terminated, s.truncated, s.info.d_min);
            if s.terminated || s.truncated {
                let d = PyDict::new(py);
                let p = s.info.pose;
                d.set_item("pose", (p.x, p.y, p.yaw.to_degrees()))?;
                d.set_item("step", s.info.step)?;
                step_info(&d, &s.info)?;
                ended.push((i, d));
            }
        }
        Ok((offset, ended))
    }

    /// The environments.
    fn __len__(&self) -> usize {
        self.venv.len()
    }

    /// Threads stepping them.
    #[getter]
    fn threads(&self) -> usize {
        self.venv.threads()
    }

    /// The task: `avoid` or `nav`.
    #[getter]
    fn task(&self) -> &'static str {
        if self.nav { "nav" } else { "avoid" }
    }
}

/// The array shapes of an observation: `laser`, `depth`, `odom`, `goal`.
#[pyfunction]
fn shapes() -> ((usize, usize), (usize, usize, usize), usize, usize) {
    ((FRAME_STACK, LASER_BEAMS), (FRAME_STACK, DEPTH_ROWS, DEPTH_COLS), 2 * ODOM_HISTORY, GOAL_DIM)
}

/// Frames in each environment's laser and depth window buffer of a `VecEnv`.
#[pyfunction]
fn window_frames() -> usize {
    WINDOW_FRAMES
}

/// The `(v m/s, w rad/s)` command of each action of the paper's Table 1, by index.
#[pyfunction]
fn actions() -> Vec<(f32, f32)> {
    mdrlat_core::TABLE_1.iter().map(|a| (a.v, a.w)).collect()
}

/// The built-in worlds' names.
#[pyfunction]
fn builtin_worlds() -> Vec<&'static str> {
    mdrlat_world::builtin::NAMES.to_vec()
}

/// Whether a task name is known (`avoid`, `nav`).
#[pyfunction]
fn check_task(name: &str) -> PyResult<String> {
    name.parse::<Task>().map(|t| t.name().to_string()).map_err(PyValueError::new_err)
}

/// The module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Env>()?;
    m.add_class::<VecEnv>()?;
    m.add_function(wrap_pyfunction!(shapes, m)?)?;
    m.add_function(wrap_pyfunction!(window_frames, m)?)?;
    m.add_function(wrap_pyfunction!(actions, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_worlds, m)?)?;
    m.add_function(wrap_pyfunction!(check_task, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
