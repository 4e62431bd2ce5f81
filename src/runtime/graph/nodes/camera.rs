//! The **camera** kind: a heavy, slow sensor. Each tick it reads the plant and publishes a
//! frame of the cartpole (`image`, `mono8`). By default the frame is a synthetic drawing, the
//! same for the same state on every machine (the rail, the cart, the pole, anti-aliased).
//! With `mujoco = 1` it is MuJoCo's offscreen render of the same scene where the machine can
//! render (an OpenGL context through EGL: a GPU, or Mesa's software renderer), and the
//! synthetic drawing where it cannot, said once in the node's log ([`super::camera_render`]).
//! Its message's origin stamp is its own stamp: the moment it looked. [`FrameGeometry`] says
//! where things are drawn (or rendered), and the **image_estimator** kind
//! (`image_estimator.rs`) reads them back.

pub use super::frame::{FrameGeometry, CART_HALF_M, POLE_LENGTH_M, SHADES};
use crate::graph::kind::{Code, KindDef, NodeContext, ParamDef, Params, Plant};
use crate::plant::{lock, SharedPlant};
use ratelab_core::msg::{AnyTopic, ImageMsg};
use ratelab_core::node::NodeState;
use ratelab_core::pixels::PixelBuffer;
use ratelab_core::ports::RustNode;
use ratelab_core::time::Nanos;

/// The smallest frame side, px.
pub const MIN_FRAME_PX: u32 = 16;
/// The largest frame side, px (a frame of 4096 × 4096 `mono8` is 16 MiB).
pub const MAX_FRAME_PX: u32 = 4096;

/// The kind's name, as a graph file spells it.
pub const NAME: &str = "camera";

/// The bytes of the frame a camera node with these (checked) parameters publishes: its
/// `width_px` × `height_px`, rounded as the node rounds them, a byte a pixel (`mono8`);
/// what a graph's worst-case memory counts for its topic (`ratelab::limits::MAX_GRAPH_QUEUE_BYTES`).
/// A parameter left out takes its default; one out of range is clamped into it.
pub fn frame_bytes(params: &toml::Table) -> u64 {
    let side = |key: &str, default: f64| -> u64 {
        let v = match params.get(key) {
            Some(toml::Value::Float(x)) if x.is_finite() => *x,
            Some(toml::Value::Integer(i)) => *i as f64,
            _ => default,
        };
        v.round()
            .clamp(f64::from(MIN_FRAME_PX), f64::from(MAX_FRAME_PX)) as u64
    };
    side("width_px", 640.0) * side("height_px", 480.0)
}

/// Its parameters: the frame's size, and where it comes from.
pub const PARAMS: &[ParamDef] = &[
    ParamDef {
        name: "width_px",
        unit: "px",
        doc: "frame width",
        default: 640.0,
        min: MIN_FRAME_PX as f64,
        max: MAX_FRAME_PX as f64,
    },
    ParamDef {
        name: "height_px",
        unit: "px",
        doc: "frame height",
        default: 480.0,
        min: MIN_FRAME_PX as f64,
        max: MAX_FRAME_PX as f64,
    },
    ParamDef {
        name: "mujoco",
        unit: "",
        doc: "1: MuJoCo's offscreen render where the machine can render, else the synthetic frame; 0: the synthetic frame",
        default: 0.0,
        min: 0.0,
        max: 1.0,
    },
];

/// The kind: no input; one `image` output; reads the plant.
pub fn def() -> KindDef {
    KindDef {
        doc: "reads the plant and publishes a frame of it (image, mono8: synthetic, or rendered by MuJoCo)",
        plant: Plant::Reads,
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        ..KindDef::of(NAME, |cx| make(&cx.node, cx.run.plant))
    }
}

/// A camera node named and set by `cx`, looking at `plant`.
fn make(cx: &NodeContext<'_>, plant: &SharedPlant) -> Result<Camera, String> {
    let (w, h) = (
        cx.param_f64("width_px", 640.0)?,
        cx.param_f64("height_px", 480.0)?,
    );
    let geometry = FrameGeometry::new(w.round() as u32, h.round() as u32);
    let mujoco = cx.param_f64("mujoco", 0.0)?;
    if mujoco != 0.0 && mujoco != 1.0 {
        return Err(format!("{}: mujoco must be 0 or 1, got {mujoco}", cx.name));
    }
    let env = super::camera_render::RENDER_ENV;
    match std::env::var(env).as_deref() {
        Err(_) | Ok("" | "on" | "off") => {}
        Ok(other) => return Err(format!("{env} must be on or off, got '{other}'")),
    }
    let render = (mujoco == 1.0)
        .then(|| super::camera_render::Render::open(geometry))
        .and_then(|opened| {
            opened
                .map_err(|e| {
                    let line = format!("{e}: drawing synthetic frames instead");
                    let warn = ratelab_core::textlog::Level::Warn;
                    ratelab_core::textlog::emit_for(Some(cx.name), None, warn, &line);
                })
                .ok()
        });
    Ok(Camera {
        name: cx.name.to_string(),
        plant: plant.clone(),
        geometry,
        render,
        out: cx.outputs.first().cloned(),
    })
}

/// A camera's state.
pub struct Camera {
    /// Its node's name (its log lines say it).
    pub name: String,
    /// The plant it looks at.
    pub plant: SharedPlant,
    /// Its frame.
    pub geometry: FrameGeometry,
    /// MuJoCo's renderer (`mujoco = 1` on a machine that renders): `None` draws the frame.
    pub render: Option<super::camera_render::Render>,
    /// Its topic, which lends the buffer a drawn frame is drawn into
    /// ([`ratelab_core::msg::AnyTopic::loan_pixels`]): in a launch whose frames cross to
    /// another process, a buffer of the process's shared-memory pool, so the frame is
    /// written once, here. `None` (no topic): memory of its own.
    pub out: Option<AnyTopic>,
}

impl RustNode for Camera {
    type Input = ();
    type Output = ImageMsg;

    fn save(&self) -> Option<NodeState> {
        // A camera keeps nothing between frames.
        Some(Box::new(()))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        state.is::<()>()
    }
    /// One tick at `now`: read the plant, render or draw it, publish.
    fn tick(&mut self, now: Nanos, (): ()) -> Option<ImageMsg> {
        let state = lock(&self.plant).state();
        let rendered = match self
            .render
            .as_mut()
            .map(|r| r.frame(state.cart_pos, state.theta))
        {
            Some(Ok(px)) => Some(px),
            Some(Err(why)) => {
                self.render = None;
                let line = format!("{why}: drawing synthetic frames from here");
                let warn = ratelab_core::textlog::Level::Warn;
                ratelab_core::textlog::emit_for(Some(&self.name), Some(now), warn, &line);
                None
            }
            None => None,
        };
        let frame = match rendered {
            Some(px) => self.geometry.frame_of(px),
            None => {
                let len = self.geometry.byte_len();
                let mut px = match &self.out {
                    Some(topic) => topic.loan_pixels(len),
                    None => PixelBuffer::zeroed(len),
                };
                self.geometry
                    .draw_into(&mut px, state.cart_pos, state.theta);
                self.geometry.frame_of(px)
            }
        };
        Some(frame)
    }
}
