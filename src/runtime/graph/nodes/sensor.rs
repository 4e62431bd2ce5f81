//! The **sensor** kind: reads the plant under its lock and publishes the full state (the
//! chapter's observation) or a position measurement, with optional seeded Gaussian noise on
//! the positions. Its message's origin stamp is its own stamp: the reading.

use crate::graph::kind::{BuildContext, Code, KindDef, NodeOf, ParamDef, Params, Plant, Ports};
use crate::plant::{lock, CartPoleState, SharedPlant};
use rand_distr::{Distribution, Normal};
use ratelab_core::ids::NodeId;
use ratelab_core::msg::{Message, PositionMsg, StateMsg};
use ratelab_core::node::NodeState;
use ratelab_core::ports::RustNode;
use ratelab_core::time::Nanos;
use std::marker::PhantomData;

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
        doc: "reads the plant and publishes the state or a position measurement",
        ports: Ports::Fixed {
            inputs: vec![],
            outputs: vec![&[StateMsg::TYPE, PositionMsg::TYPE]],
        },
        plant: Plant::Reads,
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        // A sensor of the type its topic carries.
        make: Box::new(|cx: &mut BuildContext<'_>| {
            let out = cx
                .node
                .outputs
                .first()
                .ok_or("a sensor publishes one topic")?;
            if out.msg_type() == StateMsg::TYPE {
                NodeOf::bind(cx, Sensor::<StateMsg>::new(cx)?)
            } else {
                NodeOf::bind(cx, Sensor::<PositionMsg>::new(cx)?)
            }
        }),
        name: "sensor",
        uses_brain: false,
    }
}

/// A sensor node publishing readings of type `M` (the full state or a position).
pub struct Sensor<M> {
    /// The plant it reads.
    pub plant: SharedPlant,
    /// Noise on (cart position, pole angle), with its generator; `None` when noiseless.
    pub noise: Option<SensorNoise>,
    reading: PhantomData<fn() -> M>,
}

impl<M> Sensor<M> {
    /// A sensor as `cx` sets it (its noise parameters, seeded by the run's seed and its rank).
    ///
    /// # Errors
    /// One line naming the node when a noise parameter is not a number.
    pub fn new(cx: &BuildContext<'_>) -> Result<Sensor<M>, String> {
        let (pos, angle) = (
            cx.node.param_f64("noise_pos_m", 0.0)?,
            cx.node.param_f64("noise_angle_rad", 0.0)?,
        );
        Ok(Sensor {
            plant: cx.run.plant.clone(),
            noise: (pos > 0.0 || angle > 0.0)
                .then(|| SensorNoise::new(cx.node.seed, cx.node.id, pos, angle)),
            reading: PhantomData,
        })
    }
}

/// What a sensor can publish: a reading of the plant's state, with its noise.
pub trait Reading: Message {
    /// The reading of `state`, with `noise` drawn on the positions.
    fn of(state: &CartPoleState, noise: Option<&mut SensorNoise>) -> Self;
}

impl Reading for StateMsg {
    fn of(state: &CartPoleState, noise: Option<&mut SensorNoise>) -> StateMsg {
        let mut obs = state.observation();
        if let Some(n) = noise {
            obs[0] = (state.cart_pos + n.pos.sample(&mut n.rng)) as f32;
            let th = state.theta + n.angle.sample(&mut n.rng);
            obs[2] = th.cos() as f32;
            obs[3] = th.sin() as f32;
        }
        obs
    }
}

impl Reading for PositionMsg {
    fn of(state: &CartPoleState, noise: Option<&mut SensorNoise>) -> PositionMsg {
        let (mut x, mut th) = (state.cart_pos, state.theta);
        if let Some(n) = noise {
            x += n.pos.sample(&mut n.rng);
            th += n.angle.sample(&mut n.rng);
        }
        PositionMsg {
            cart_pos_m: x,
            pole_angle_rad: th,
        }
    }
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

impl<M: Reading> RustNode for Sensor<M> {
    type Input = ();
    type Output = M;

    fn save(&self) -> Option<NodeState> {
        // The noise's generator is all a sensor keeps between ticks.
        Some(Box::new(self.noise.as_ref().map(|n| n.rng.clone())))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        let Some(rng) = state.downcast_ref::<Option<rand_pcg::Pcg64>>() else {
            return false;
        };
        if let (Some(n), Some(rng)) = (&mut self.noise, rng) {
            n.rng = rng.clone();
        }
        true
    }
    /// One tick: read the plant, publish (its reading's origin is the tick: the reading).
    fn tick(&mut self, _now: Nanos, (): ()) -> Option<M> {
        let state = lock(&self.plant).state();
        Some(M::of(&state, self.noise.as_mut()))
    }
}
