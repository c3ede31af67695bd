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
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArray4, PyArrayMethods, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PySlice};

/// The simulator's name for a collision (`bumper`, `pedestrian`, `laser`), as `episodes.csv`
/// writes it.
fn collision_name(c: &Collision) -> &'static str {
    mdrlat_eval::protocol::collision_kind(c)
}

fn sim_error(e: mdrlat_sim::SimError) -> PyErr {
    match e {
        // The caller's value, not the simulator's state.
        mdrlat_sim::SimError::BadPose { .. } | mdrlat_sim::SimError::Config(_) => {
            PyValueError::new_err(e.to_string())
        }
        _ => PyRuntimeError::new_err(e.to_string()),
    }
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
/// soon, and new memory is better not zeroed first: zeroing and then copying took a large
/// share of a one-env step; see `docs/performance.md`, *Python vector env speed*).
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
/// `WINDOW_FRAMES − FRAME_STACK + 1` steps). 16 frames with plain stores beat 32 with
/// non-temporal ones on both CPUs measured (a step writes ~5 frames of 82 KB for 4
/// environments; 16-frame windows, 5.2 MB for 4, stay in the last-level cache, where
/// plain stores also leave the frames for the caller to read); on a Sapphire Rapids Xeon plain
/// stores were the faster at every size from 8 to 32 frames (figures in `docs/performance.md`,
/// *Python vector env speed*).
const WINDOW_FRAMES: usize = 16;

/// The most environments (and threads) a vector env takes.
const MAX_ENVS: usize = 4096;

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
                let to = &mut buf[offset * n..(offset + FRAME_STACK) * n];
                stack.write_stacked(to, |frame, to| to.copy_from_slice(frame));
            } else {
                let newest = offset + FRAME_STACK - 1;
                buf[newest * n..(newest + 1) * n].copy_from_slice(stack.latest());
            }
        }
        write_vectors(obs, self.odom, self.goal);
    }
}

/// An environment's places in the buffers: its current observation's window and its
/// last episode's final observation.
struct EnvSlot<'a> {
    now: ObsSlot<'a>,
    last: ObsSlot<'a>,
}

/// One observation of each of N environments as numpy arrays (float32, C order): `laser`
/// `(N, F, 512)`, `depth` `(N, F, 128, 160)` with `F` frames each, `odom` `(N, 6)`, and
/// `goal` `(N, 3)` or `(0, 3)` without the navigation task.
struct ObsArrays {
    laser: Py<PyArray3<f32>>,
    depth: Py<PyArray4<f32>>,
    odom: Py<PyArray2<f32>>,
    goal: Py<PyArray2<f32>>,
    /// Frames per environment (`F`), and whether there are goals.
    frames: usize,
    nav: bool,
}

impl ObsArrays {
    fn zeros(py: Python<'_>, n: usize, frames: usize, nav: bool) -> Self {
        Self {
            laser: PyArray3::zeros(py, [n, frames, LASER_BEAMS], false).unbind(),
            depth: PyArray4::zeros(py, [n, frames, DEPTH_ROWS, DEPTH_COLS], false).unbind(),
            odom: PyArray2::zeros(py, [n, 2 * ODOM_HISTORY], false).unbind(),
            goal: PyArray2::zeros(py, [if nav { n } else { 0 }, GOAL_DIM], false).unbind(),
            frames,
            nav,
        }
    }

    /// Each environment's rows, checked against `n` environments; errors name the arrays
    /// `{prefix}laser` and so on.
    ///
    /// # Safety
    /// As [`values`]: nothing else may use the arrays while the slots live.
    #[allow(unsafe_code)]
    unsafe fn slots<'a>(
        &'a self,
        py: Python<'a>,
        prefix: &str,
        n: usize,
    ) -> PyResult<Vec<ObsSlot<'a>>> {
        let (f, goal) = (self.frames, if self.nav { GOAL_DIM } else { 0 });
        // SAFETY: the caller's promise; each array is taken once.
        let (laser, depth, odom, goals) = unsafe {
            (
                values(py, (prefix, "laser"), &self.laser, n * f * LASER_BEAMS)?,
                values(py, (prefix, "depth"), &self.depth, n * f * DEPTH_LEN)?,
                values(py, (prefix, "odom"), &self.odom, n * 2 * ODOM_HISTORY)?,
                values(py, (prefix, "goal"), &self.goal, n * goal)?,
            )
        };
        // `chunks_exact_mut(0)` panics: goal-less arrays give every slot an empty goal.
        let mut goals = goals.chunks_exact_mut(goal.max(1));
        Ok(laser
            .chunks_exact_mut(f * LASER_BEAMS)
            .zip(depth.chunks_exact_mut(f * DEPTH_LEN))
            .zip(odom.chunks_exact_mut(2 * ODOM_HISTORY))
            .map(|((laser, depth), odom)| ObsSlot {
                laser,
                depth,
                odom,
                goal: goals.next().unwrap_or_default(),
            })
            .collect())
    }

    /// The arrays into `d`, their names prefixed by `prefix`.
    fn add_to(&self, py: Python<'_>, d: &Bound<'_, PyDict>, prefix: &str) -> PyResult<()> {
        d.set_item(format!("{prefix}laser"), self.laser.bind(py))?;
        d.set_item(format!("{prefix}depth"), self.depth.bind(py))?;
        d.set_item(format!("{prefix}odom"), self.odom.bind(py))?;
        d.set_item(format!("{prefix}goal"), self.goal.bind(py))
    }
}

/// The numpy arrays a [`VecEnv`] writes into, made with it: the current observations
/// (`laser` and `depth` frame windows of [`WINDOW_FRAMES`] frames each); the final
/// observations of ended episodes (`final_*`, whole stacks); a step's `rewards`,
/// `terminated` and `truncated`, `(N,)` each; and the observation dict of every
/// window position (views of the windows). Made once instead of passed in with every step:
/// extracting 13 numpy arguments and checking their borrows every call was measurable, and it
/// falls in the serial stretch between steps during which the worker threads wait
/// (`docs/performance.md`, *Python vector env speed*).
struct VecBuffers {
    now: ObsArrays,
    last: ObsArrays,
    rewards: Py<PyArray1<f32>>,
    terminated: Py<PyArray1<bool>>,
    truncated: Py<PyArray1<bool>>,
    /// `windows[k]`: the observation dict of frames `k..k + 4` of the windows.
    windows: Vec<Py<PyDict>>,
}

/// Every buffer of a [`VecBuffers`] as Rust slices, for one call.
struct BufferViews<'a> {
    slots: Vec<EnvSlot<'a>>,
    rewards: &'a mut [f32],
    terminated: &'a mut [bool],
    truncated: &'a mut [bool],
}

/// `a`'s values as a slice of `len` values, or an error naming the buffer if it no longer
/// holds that many (an array resized from Python).
///
/// # Safety
/// Nothing else may read or write `a`'s memory while the slice lives (see
/// [`VecBuffers::views`]).
#[allow(unsafe_code, clippy::mut_from_ref)]
unsafe fn values<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    py: Python<'a>,
    (prefix, key): (&str, &str),
    a: &'a Py<numpy::PyArray<T, D>>,
    len: usize,
) -> PyResult<&'a mut [T]> {
    if !a.bind(py).is_c_contiguous() {
        return Err(PyRuntimeError::new_err(format!(
            "buffer '{prefix}{key}' is no longer C-contiguous"
        )));
    }
    // SAFETY: the caller's promise.
    let s = unsafe { a.bind(py).as_slice_mut() }
        .map_err(|e| PyRuntimeError::new_err(format!("buffer '{prefix}{key}': {e}")))?;
    if s.len() != len {
        return Err(PyRuntimeError::new_err(format!(
            "buffer '{prefix}{key}' holds {} values, expected {len}",
            s.len()
        )));
    }
    Ok(s)
}

impl VecBuffers {
    /// Zeroed buffers for `n` environments (goals only with `nav`).
    fn new(py: Python<'_>, n: usize, nav: bool) -> PyResult<Self> {
        let b = Self {
            now: ObsArrays::zeros(py, n, WINDOW_FRAMES, nav),
            last: ObsArrays::zeros(py, n, FRAME_STACK, nav),
            rewards: PyArray1::zeros(py, n, false).unbind(),
            terminated: PyArray1::zeros(py, n, false).unbind(),
            truncated: PyArray1::zeros(py, n, false).unbind(),
            windows: Vec::new(),
        };
        let windows = (0..=WINDOW_FRAMES - FRAME_STACK)
            .map(|k| {
                let end = (k + FRAME_STACK) as isize;
                let frames = (PySlice::full(py), PySlice::new(py, k as isize, end, 1));
                let d = PyDict::new(py);
                d.set_item("laser", b.now.laser.bind(py).get_item(frames.clone())?)?;
                d.set_item("depth", b.now.depth.bind(py).get_item(frames)?)?;
                d.set_item("odom", b.now.odom.bind(py))?;
                if nav {
                    d.set_item("goal", b.now.goal.bind(py))?;
                }
                Ok(d.unbind())
            })
            .collect::<PyResult<_>>()?;
        Ok(Self { windows, ..b })
    }

    /// Every buffer as a Rust slice, checked against `n` environments.
    ///
    /// Sound because these arrays are this object's own: `&mut self` keeps Rust from
    /// taking a second set, and the class documents that no other thread may touch them
    /// during a call (the GIL is released then), as with any numpy buffer a native
    /// function fills.
    #[allow(unsafe_code)]
    fn views<'a>(&'a mut self, py: Python<'a>, n: usize) -> PyResult<BufferViews<'a>> {
        // SAFETY: see above; each array is taken once.
        unsafe {
            let now = self.now.slots(py, "", n)?;
            let last = self.last.slots(py, "final_", n)?;
            Ok(BufferViews {
                slots: now.into_iter().zip(last).map(|(now, last)| EnvSlot { now, last }).collect(),
                rewards: values(py, ("", "rewards"), &self.rewards, n)?,
                terminated: values(py, ("", "terminated"), &self.terminated, n)?,
                truncated: values(py, ("", "truncated"), &self.truncated, n)?,
            })
        }
    }

    /// The arrays by name, for Python (`final_*` for the final observations).
    fn dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        self.now.add_to(py, &d, "")?;
        self.last.add_to(py, &d, "final_")?;
        d.set_item("rewards", self.rewards.bind(py))?;
        d.set_item("terminated", self.terminated.bind(py))?;
        d.set_item("truncated", self.truncated.bind(py))?;
        Ok(d)
    }
}

/// What [`VecEnv::step`] returns: Gymnasium's `(observations, rewards, terminated,
/// truncated, infos)` and the ended episodes `(i, final_info)`.
type StepTuple<'py> = (
    Bound<'py, PyDict>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyDict>,
    Vec<(usize, Bound<'py, PyDict>)>,
);

/// N environments stepped in parallel on all cores by the Rust `VecEnv`, the GIL
/// released, writing into numpy buffers of its own (no arrays made per step but the info's
/// `d_min`): each environment's thread writes its observations right after its step.
/// Finished episodes restart at once (Gymnasium's same-step autoreset); their final
/// observations go to the `final_*` buffers. No other thread may read or write the buffers
/// (or views of them, such as the observations) while `reset` or `step` runs.
#[pyclass(module = "mdrlat._core")]
pub struct VecEnv {
    venv: mdrlat_sim::VecEnv,
    nav: bool,
    buffers: VecBuffers,
    actions: Vec<mdrlat_core::Action>,
    /// Where the observations' 4-frame windows start in the laser and depth buffers.
    offset: usize,
    /// `reset` has run.
    started: bool,
    /// `True` for every environment: the info's `_d_min` mask.
    all: Vec<bool>,
}

#[pymethods]
impl VecEnv {
    /// `num_envs` environments in `world` with the settings `config_json` (as [`Env`]),
    /// on `threads` threads (0: every core).
    #[new]
    #[pyo3(signature = (world, config_json = "{}", num_envs = 1, threads = 0))]
    fn new(
        py: Python<'_>,
        world: &str,
        config_json: &str,
        num_envs: usize,
        threads: usize,
    ) -> PyResult<Self> {
        if num_envs == 0 || num_envs > MAX_ENVS {
            return Err(PyValueError::new_err(format!(
                "num_envs {num_envs}: expected 1 to {MAX_ENVS}"
            )));
        }
        let (loaded, config) = load(world, config_json)?;
        let nav = config.task == Task::Nav;
        let scene =
            std::sync::Arc::new(mdrlat_sim::StaticScene::new(std::sync::Arc::new(loaded), &config));
        let venv = mdrlat_sim::VecEnv::new(scene, config, num_envs, threads)
            .map_err(|e| PyValueError::new_err(format!("world '{world}': {e}")))?;
        Ok(Self {
            venv,
            nav,
            buffers: VecBuffers::new(py, num_envs, nav)?,
            actions: Vec::with_capacity(num_envs),
            offset: 0,
            started: false,
            all: vec![true; num_envs],
        })
    }

    /// The numpy buffers the environments write into, by name (see [`VecBuffers`]).
    fn buffers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.buffers.dict(py)
    }

    /// Starts an episode in every environment: environment `i` with `seeds[i]` (`None`:
    /// its stream goes on), exactly as `Env.reset(seed=seeds[i])`; writes the observations
    /// into the buffers (windows at frame 0). Returns the observations and each
    /// environment's pose `(x, y, yaw_deg)`.
    #[allow(clippy::type_complexity)]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
    ) -> PyResult<(Bound<'py, PyDict>, Vec<(f32, f32, f32)>)> {
        let n = self.venv.len();
        if seeds.len() != n {
            return Err(PyValueError::new_err(format!(
                "{} seeds for {n} environments",
                seeds.len()
            )));
        }
        // The buffers are checked first: a failure leaves the environments as they were.
        let mut views = self.buffers.views(py, n)?;
        let venv = &mut self.venv;
        py.detach(|| -> Result<(), mdrlat_sim::SimError> {
            for (i, seed) in seeds.iter().enumerate() {
                venv.reset_env(i, *seed, None)?;
            }
            Ok(())
        })
        .map_err(sim_error)?;
        for (i, slot) in views.slots.iter_mut().enumerate() {
            slot.now.write(&self.venv.observation(i), 0, true);
        }
        drop(views);
        (self.offset, self.started) = (0, true);
        let poses = (0..n)
            .map(|i| {
                let p = self.venv.env(i).pose();
                (p.x, p.y, p.yaw.to_degrees())
            })
            .collect();
        Ok((self.buffers.windows[0].bind(py).clone(), poses))
    }

    /// One step of every environment with `actions[i]` (0–9, an int64 array of any shape
    /// holding one per environment): writes the observations (after any autoreset), the
    /// rewards, `terminated` and `truncated` into the buffers. Returns Gymnasium's
    /// `(observations, rewards, terminated, truncated, infos)` — the observations the views
    /// of the windows' new position, the arrays the buffers themselves, `infos` with
    /// `d_min` (a new array) — and, for every environment whose episode ended, `(i, final_info)` (its
    /// final observation is row `i` of the `final_*` buffers).
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: numpy::PyReadonlyArrayDyn<'py, i64>,
    ) -> PyResult<StepTuple<'py>> {
        if !self.started {
            return Err(PyRuntimeError::new_err("step() before reset(): call reset() first"));
        }
        let n = self.venv.len();
        if actions.len() != n {
            return Err(PyValueError::new_err(format!(
                "{} actions for {n} environments",
                actions.len()
            )));
        }
        self.actions.clear();
        for (i, &a) in actions.as_array().iter().enumerate() {
            let action =
                usize::try_from(a).ok().and_then(mdrlat_core::Action::new).ok_or_else(|| {
                    PyValueError::new_err(format!("actions[{i}] = {a}: expected 0 to 9"))
                })?;
            self.actions.push(action);
        }
        // The windows slide on by a frame, or start again from the front of the buffers.
        let wrap = self.offset + 1 + FRAME_STACK > WINDOW_FRAMES;
        let offset = if wrap { 0 } else { self.offset + 1 };
        let steps = {
            // The buffers' slices live only in this block: no Python object is made (no
            // code that might touch the arrays runs) while they do.
            let views = self.buffers.views(py, n)?;
            let BufferViews { mut slots, rewards, terminated, truncated } = views;
            let write = move |slot: &mut EnvSlot<'_>,
                              _: &mdrlat_sim::VecStep,
                              last: Option<&Observation>,
                              now: &Observation| {
                if let Some(last) = last {
                    slot.last.write(last, 0, true);
                }
                slot.now.write(now, offset, wrap || last.is_some());
            };
            let (venv, acts) = (&mut self.venv, &self.actions);
            let steps = py
                .detach(|| venv.step_into(acts, &mut slots, &write).map(<[_]>::to_vec))
                .map_err(sim_error)?;
            for (i, s) in steps.iter().enumerate() {
                (rewards[i], terminated[i], truncated[i]) = (s.reward, s.terminated, s.truncated);
            }
            steps
        };
        self.offset = offset;
        let mut ended = Vec::new();
        for (i, s) in steps.iter().enumerate().filter(|(_, s)| s.terminated || s.truncated) {
            let d = PyDict::new(py);
            let p = s.info.pose;
            d.set_item("pose", (p.x, p.y, p.yaw.to_degrees()))?;
            d.set_item("step", s.info.step)?;
            step_info(&d, &s.info)?;
            ended.push((i, d));
        }
        let infos = PyDict::new(py);
        infos.set_item("d_min", PyArray1::from_iter(py, steps.iter().map(|s| s.info.d_min)))?;
        infos.set_item("_d_min", PyArray1::from_slice(py, &self.all))?;
        let b = &self.buffers;
        Ok((
            b.windows[offset].bind(py).clone(),
            b.rewards.bind(py).clone(),
            b.terminated.bind(py).clone(),
            b.truncated.bind(py).clone(),
            infos,
            ended,
        ))
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
    m.add_function(wrap_pyfunction!(actions, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_worlds, m)?)?;
    m.add_function(wrap_pyfunction!(check_task, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MAX_ENVS", MAX_ENVS)?;
    Ok(())
}
