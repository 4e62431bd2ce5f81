//! The plant: the chapter's cartpole, simulated by MuJoCo 3.17 (through `mujoco-rs`).
//!
//! The plant owns simulated time: one [`CartPole::step`] is one 50 Hz plant step (one actuator tick)
//! (the action held for [`FRAME_SKIP`] physics steps of 10 ms). The model is
//! `assets/cartpole.xml`, written from the course env's physical facts: a 1 kg cart on a
//! frictionless ±2.9 m slider driven by one motor (gear 10, ctrl in [-1, 1]); a 0.1 kg,
//! 1 m capsule pole on an undamped hinge about +y; no contacts; `implicitfast`.

use mujoco_rs::prelude::*;
use ratelab_core::np_random::NumpyGenerator;
use ratelab_core::time::Nanos;
use std::sync::{Arc, Mutex, MutexGuard};

pub use ratelab_core::plant::*;

const MJCF: &str = include_str!("assets/cartpole.xml");

/// Errors building the plant.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// MuJoCo rejected the model (a bug in the shipped MJCF).
    #[error("MuJoCo could not load the cartpole model: {0}")]
    Model(String),
    /// A state given to [`CartPole::load`] is not this model's (its length, in numbers).
    #[error("a plant state of {0} numbers is not the cartpole's")]
    State(usize),
}

/// What [`CartPole::save`] captures: MuJoCo's integration state and the step count.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantState {
    mj: Vec<f64>,
    steps: u64,
}

/// The parts of MuJoCo's state a capture takes: everything `mj_step` integrates from.
const INTEGRATION: u32 = MjtState::mjSTATE_INTEGRATION as u32;

/// The cartpole's full state, in SI units (θ wrapped to [-π, π)).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CartPoleState {
    /// Cart position, m.
    pub cart_pos: f64,
    /// Cart velocity, m/s.
    pub cart_vel: f64,
    /// Pole angle from upright, rad; positive tips toward +x.
    pub theta: f64,
    /// Pole angular velocity, rad/s.
    pub pole_angvel: f64,
}

impl CartPoleState {
    /// Outside the fall limits?
    pub fn terminated(&self) -> bool {
        self.theta.abs() > THETA_LIMIT_RAD || self.cart_pos.abs() > CART_LIMIT_M
    }

    /// `[cart_pos m, cart_vel m/s, theta rad, pole_angvel rad/s]`, the order of
    /// [`ratelab_core::estimate::COMPONENTS`].
    pub fn as_array(&self) -> [f64; 4] {
        [self.cart_pos, self.cart_vel, self.theta, self.pole_angvel]
    }

    /// The observation the sensor publishes (float32, as the course's env).
    pub fn observation(&self) -> Observation {
        [
            self.cart_pos as f32,
            self.cart_vel as f32,
            self.theta.cos() as f32,
            self.theta.sin() as f32,
            self.pole_angvel as f32,
        ]
    }
}

/// What one plant step did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutcome {
    /// The state after the step.
    pub state: CartPoleState,
    /// The control actually applied (clipped to [-1, 1]).
    pub applied: f64,
    /// True when the step ended outside the fall limits.
    pub terminated: bool,
}

/// The plant shared by the sensors (read) and the actuator (steps it).
pub type SharedPlant = Arc<Mutex<CartPole>>;

/// Lock the shared plant, tolerating poison (each holder leaves it consistent).
pub fn lock(p: &SharedPlant) -> MutexGuard<'_, CartPole> {
    p.lock().unwrap_or_else(|e| e.into_inner())
}

/// The MuJoCo cartpole. `Send`, so the real clock can share it behind a lock.
pub struct CartPole {
    data: MjData<Box<MjModel>>,
    steps: u64,
}

impl CartPole {
    /// Load the model (at rest, upright); call [`CartPole::reset`] before a run.
    ///
    /// # Errors
    /// [`PlantError::Model`] if MuJoCo rejects the MJCF.
    pub fn new() -> Result<Self, PlantError> {
        // Parse and compile the MJCF once per process; every plant gets a copy
        // (`mj_copyModel`), which is much cheaper than compiling (sweeps build thousands).
        static COMPILED: Mutex<Option<MjModel>> = Mutex::new(None);
        let mut compiled = COMPILED.lock().unwrap_or_else(|e| e.into_inner());
        if compiled.is_none() {
            *compiled =
                Some(MjModel::from_xml_string(MJCF).map_err(|e| PlantError::Model(e.to_string()))?);
        }
        let model = compiled.as_ref().expect("compiled above").clone();
        drop(compiled);
        Ok(Self {
            data: MjData::new(Box::new(model)),
            steps: 0,
        })
    }

    /// Reset to the course env's seeded start: with `Generator(PCG64(seed))`, draw
    /// `(cart_pos, θ)` then `(cart_vel, pole_angvel)`, each uniform in [-0.05, 0.05].
    pub fn reset(&mut self, seed: u64) -> CartPoleState {
        let mut rng = NumpyGenerator::new(seed);
        let mut draw = || rng.uniform(-RESET_NOISE, RESET_NOISE);
        let (cart_pos, theta) = (draw(), draw());
        let (cart_vel, pole_angvel) = (draw(), draw());
        self.data.reset();
        self.data.qpos_mut().copy_from_slice(&[cart_pos, theta]);
        self.data
            .qvel_mut()
            .copy_from_slice(&[cart_vel, pole_angvel]);
        self.data.ctrl_mut()[0] = 0.0;
        self.data.forward();
        self.steps = 0;
        self.state()
    }

    /// The current state.
    pub fn state(&self) -> CartPoleState {
        let qpos = self.data.qpos();
        let qvel = self.data.qvel();
        CartPoleState {
            cart_pos: qpos[0],
            cart_vel: qvel[0],
            theta: wrap_angle(qpos[1]),
            pole_angvel: qvel[1],
        }
    }

    /// The current observation.
    pub fn observe(&self) -> Observation {
        self.state().observation()
    }

    /// Apply `action` (clipped to [-1, 1]; a non-finite action must be filtered by the
    /// caller) for one plant step of [`FRAME_SKIP`] physics steps.
    pub fn step(&mut self, action: f32) -> StepOutcome {
        let applied = f64::from(action).clamp(-1.0, 1.0);
        self.data.ctrl_mut()[0] = applied;
        for _ in 0..FRAME_SKIP {
            self.data.step();
        }
        self.steps += 1;
        let state = self.state();
        StepOutcome {
            state,
            applied,
            terminated: state.terminated(),
        }
    }

    /// MuJoCo's whole integration state (`mj_getState` with `mjSTATE_INTEGRATION`: time,
    /// positions, velocities, actuator activations, warm start, controls, …) and the step
    /// count, for a capture of the run ([`crate::runcore`]): [`CartPole::load`] of it and
    /// stepping on gives, bit for bit, what stepping on from here gives.
    pub fn save(&self) -> PlantState {
        PlantState {
            mj: self.data.state(INTEGRATION).into_vec(),
            steps: self.steps,
        }
    }

    /// Put back what [`CartPole::save`] gave (`mj_setState`).
    ///
    /// # Errors
    /// [`PlantError::State`] when `state` is not this model's (its length differs).
    pub fn load(&mut self, state: &PlantState) -> Result<(), PlantError> {
        if state.mj.len() != self.data.model().state_size(INTEGRATION) {
            return Err(PlantError::State(state.mj.len()));
        }
        self.data
            .set_state(&state.mj, INTEGRATION)
            .map_err(|_| PlantError::State(state.mj.len()))?;
        self.steps = state.steps;
        Ok(())
    }

    /// Plant steps taken since the last reset.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Simulated time since the last reset (plant steps × 20 ms).
    pub fn sim_time(&self) -> Nanos {
        Nanos(self.steps * CONTROL_PERIOD.0)
    }

    /// Raw MuJoCo simulated time, s (for cross-checks).
    pub fn mujoco_time_s(&self) -> f64 {
        self.data.time()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_zero_reset_matches_the_course_env() {
        let mut plant = CartPole::new().unwrap();
        let s = plant.reset(0);
        assert_eq!(s.cart_pos, 0.013696168732145436);
        assert_eq!(s.cart_vel, -0.045902647606380534);
        assert_eq!(s.theta, -0.02302132862361317);
        assert_eq!(s.pole_angvel, -0.04834723644714709);
        // Resetting again gives the same start; another seed gives another.
        assert_eq!(plant.reset(0), s);
        assert_ne!(plant.reset(1), s);
    }

    #[test]
    fn unactuated_pole_falls_toward_its_lean() {
        let mut plant = CartPole::new().unwrap();
        plant.reset(0); // θ < 0: leans toward -x
        let mut last = plant.state();
        for _ in 0..200 {
            let out = plant.step(0.0);
            last = out.state;
            if out.terminated {
                break;
            }
        }
        assert!(last.theta < -THETA_LIMIT_RAD, "{last:?}");
        assert!((plant.mujoco_time_s() - plant.sim_time().as_secs_f64()).abs() < 1e-9);
    }

    #[test]
    fn wrap_angle_range() {
        use std::f64::consts::PI;
        assert!((wrap_angle(0.1) - 0.1).abs() < 1e-15);
        assert!((wrap_angle(PI + 0.1) - (-PI + 0.1)).abs() < 1e-12);
        assert_eq!(wrap_angle(PI), -PI);
        assert_eq!(wrap_angle(0.0), 0.0);
    }
}
