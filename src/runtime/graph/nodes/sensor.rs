//! The **sensor** kind: reads the plant under its lock and publishes the full state (the
//! chapter's observation) or a position measurement, with optional seeded Gaussian noise on
//! the positions. Its message's origin stamp is its own stamp: the reading.

use crate::graph::kind::{BuildContext, Code, KindDef, ParamDef, Params, Plant, Ports, Work};
use crate::plant::{lock, SharedPlant};
use rand_distr::{Distribution, Normal};
use ratelab_core::ids::NodeId;
use ratelab_core::msg::{Message, PositionMsg, StateMsg};
use ratelab_core::node::Flow;
use ratelab_core::publisher::Publisher;
use ratelab_core::time::Nanos;

/// Its parameters: noise on each measured position.
pub const PARAMS: &[ParamDef] = &[
    ParamDef {
        name: "noise_pos_m",
        unit: "m",
        doc: "standard deviation of Gaussian noise on the cart position",
        default: 0.0,
        min: 0.0,
        max: 1.0,
    },
    ParamDef {
        name: "noise_angle_rad",
        unit: "rad",
        doc: "standard deviation of Gaussian noise on the pole angle",
        default: 0.0,
        min: 0.0,
        max: 0.5,
    },
];

/// The kind: no input; one output of `state` or `position`; reads the plant.
pub fn def() -> KindDef {
    KindDef {
        name: "sensor",
        doc: "reads the plant and publishes the state or a position measurement",
        ports: Ports::Fixed {
            inputs: vec![],
            outputs: vec![&[StateMsg::TYPE, PositionMsg::TYPE]],
        },
        plant: Plant::Reads,
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        uses_brain: false,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            let out = cx.outputs.first().ok_or("a sensor publishes one topic")?;
            let output = match (
                out.publisher::<StateMsg>(cx.outbox),
                out.publisher::<PositionMsg>(cx.outbox),
            ) {
                (Some(p), _) => SensorOutput::State(p),
                (None, Some(p)) => SensorOutput::Position(p),
                (None, None) => {
                    return Err(format!("sensor '{}' publishes state or position", cx.name))
                }
            };
            let (pos, angle) = (
                cx.param_f64("noise_pos_m", 0.0)?,
                cx.param_f64("noise_angle_rad", 0.0)?,
            );
            Ok(Box::new(Sensor {
                plant: cx.plant.clone(),
                output,
                noise: (pos > 0.0 || angle > 0.0)
                    .then(|| SensorNoise::new(cx.seed, cx.id, pos, angle)),
            }) as Box<dyn Work>)
        }),
    }
}

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

impl Work for Sensor {
    fn save(&self) -> Option<ratelab_core::node::NodeState> {
        // The noise's generator is all a sensor keeps between ticks.
        Some(Box::new(self.noise.as_ref().map(|n| n.rng.clone())))
    }
    fn load(&mut self, state: &ratelab_core::node::NodeState) -> bool {
        let Some(rng) = state.downcast_ref::<Option<rand_pcg::Pcg64>>() else {
            return false;
        };
        if let (Some(n), Some(rng)) = (&mut self.noise, rng) {
            n.rng = rng.clone();
        }
        true
    }
    /// One tick at `now`: read the plant, publish.
    fn tick(&mut self, now: Nanos) -> Flow {
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
