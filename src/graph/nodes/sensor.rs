//! The **sensor**: reads the plant under its lock and publishes the full state (the
//! chapter's observation) or a position measurement, with optional seeded Gaussian noise on
//! the positions. Its message's origin stamp is its own stamp: the reading.

use crate::graph::spec::NodeId;
use crate::graph::{lock, SharedPlant};
use crate::msg::{PositionMsg, StateMsg};
use crate::node::Flow;
use crate::publisher::Publisher;
use crate::time::Nanos;
use rand_distr::{Distribution, Normal};

/// A sensor's state.
pub struct Sensor {
    /// The plant it reads.
    pub plant: SharedPlant,
    /// Where it publishes.
    pub output: SensorOutput,
    /// Noise on (cart position, pole angle), with its generator; `None` when noiseless.
    pub noise: Option<SensorNoise>,
}

/// A sensor's topic: full state or positions.
pub enum SensorOutput {
    /// Publishes the full state.
    State(Publisher<StateMsg>),
    /// Publishes positions.
    Position(Publisher<PositionMsg>),
}

/// Seeded Gaussian measurement noise.
pub struct SensorNoise {
    /// The generator (PCG64, seeded from the run's seed and the node's rank).
    pub rng: rand_pcg::Pcg64,
    /// Cart-position noise, m (standard deviation).
    pub pos: Normal<f64>,
    /// Pole-angle noise, rad (standard deviation).
    pub angle: Normal<f64>,
}

impl SensorNoise {
    /// Noise with these standard deviations, seeded by `(seed, node)`: same seed, same draws.
    ///
    /// # Panics
    /// Never for the finite, non-negative deviations a validated graph holds.
    pub fn new(seed: u64, node: NodeId, pos_m: f64, angle_rad: f64) -> SensorNoise {
        SensorNoise {
            rng: rand_pcg::Pcg64::new(u128::from(seed), 0xda3e_39cb_94b9_5bdb ^ node.0 as u128),
            pos: Normal::new(0.0, pos_m).expect("validated deviation"),
            angle: Normal::new(0.0, angle_rad).expect("validated deviation"),
        }
    }
}

impl Sensor {
    /// One tick at `now`: read the plant, publish.
    pub fn tick(&mut self, now: Nanos) -> Flow {
        let state = lock(&self.plant).state();
        match &self.output {
            SensorOutput::State(t) => {
                let mut obs = state.observation();
                if let Some(n) = &mut self.noise {
                    obs[0] = (state.cart_pos + n.pos.sample(&mut n.rng)) as f32;
                    let th = state.theta + n.angle.sample(&mut n.rng);
                    obs[2] = th.cos() as f32;
                    obs[3] = th.sin() as f32;
                }
                t.publish(obs, now, Some(now));
            }
            SensorOutput::Position(t) => {
                let (mut x, mut th) = (state.cart_pos, state.theta);
                if let Some(n) = &mut self.noise {
                    x += n.pos.sample(&mut n.rng);
                    th += n.angle.sample(&mut n.rng);
                }
                let m = PositionMsg {
                    cart_pos_m: x,
                    pole_angle_rad: th,
                };
                t.publish(m, now, Some(now));
            }
        }
        Flow::Continue
    }
}
