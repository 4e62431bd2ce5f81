//! MuJoCo's offscreen render of the cartpole, for the **camera** kind's `mujoco = 1`: the
//! same rail, cart and pole as `assets/cartpole.xml`, seen through an orthographic camera
//! placed so that a metre spans exactly the pixels the synthetic frame gives it
//! ([`FrameGeometry`]), flat-shaded in the synthetic frame's [`SHADES`] on black. So the
//! **image_estimator** kind reads a rendered frame as it reads a drawn one.
//!
//! Rendering needs an OpenGL context: mujoco-rs opens one offscreen through EGL (a GPU's, or
//! Mesa's software renderer, llvmpipe). A machine without EGL cannot render: [`Render::open`]
//! then says why in one line, and the camera draws its synthetic frame instead. The context
//! lives on a thread of its own, which renders what the camera asks, so the node may tick
//! on any thread (the real clock gives each node its own; a clock switch hands them back).
//!
//! A rendered frame is the same for the same state on one machine and driver, not across
//! machines (rasterizers differ in their last bits): a run with `mujoco = 1` replays on the
//! machine that made it, and only the synthetic frame is byte-identical everywhere.

use super::frame::{FrameGeometry, CART_HALF_M, POLE_LENGTH_M, SHADES};
use crossbeam_channel::{bounded, Receiver, Sender};
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;

/// How long the camera waits for a frame before it draws the synthetic one instead (a
/// render of a 4096 × 4096 frame in software takes well under a second).
const FRAME_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

/// How long opening the renderer may take before the camera draws instead (EGL's start-up,
/// MuJoCo's context: well under a second in software).
const OPEN_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// The environment variable that turns rendering off (`off`: every camera draws, as on a
/// machine that cannot render; unset, empty or `on`: cameras with `mujoco = 1` render).
pub const RENDER_ENV: &str = "RATELAB_RENDER";

/// The scene to render for a frame of `g`: the cartpole's geometry with every material
/// flat (no lights, no specular; an emission of 0.7 of the colour, which MuJoCo's own
/// ambient of 0.3 of it brings to the colour exactly: the test finds each of [`SHADES`]),
/// edges smoothed by 4× multisampling as the drawing's are, and the camera `side`, orthographic, looking
/// along +y at the plane of the cart and pole, its view `height_px / scale` metres tall and
/// centred `(0.85 − 0.5) · height_px / scale` above the hinge (where the synthetic frame
/// puts it).
pub fn scene_xml(g: &FrameGeometry) -> String {
    let (w, h) = (f64::from(g.width), f64::from(g.height));
    let view_m = h / g.scale;
    let centre_z = (g.hinge_row - h / 2.0) / g.scale;
    let grey = |v: u8| {
        let c = f64::from(v) / 255.0;
        format!("{c:.6} {c:.6} {c:.6} 1")
    };
    let (rail, cart, pole) = SHADES;
    let (cx, cz) = CART_HALF_M;
    format!(
        r#"<mujoco model="cartpole-camera">
  <compiler angle="radian"/>
  <visual>
    <global offwidth="{w}" offheight="{h}"/>
    <headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0" active="0"/>
    <quality offsamples="4" shadowsize="0"/>
    <rgba haze="0 0 0 1"/>
  </visual>
  <default>
    <geom contype="0" conaffinity="0" material="flat"/>
  </default>
  <asset>
    <material name="flat" emission="0.7" specular="0" shininess="0" reflectance="0"/>
  </asset>
  <worldbody>
    <camera name="side" mode="fixed" projection="orthographic" fovy="{view_m}" pos="0 -10 {centre_z}" xyaxes="1 0 0 0 0 1"/>
    <geom name="rail" type="box" pos="0 0 0" size="2.9 0.01 0.01" rgba="{rail}"/>
    <body name="cart" pos="0 0 0">
      <joint name="slider" type="slide" axis="1 0 0"/>
      <geom name="cart" type="box" size="{cx} 0.05 {cz}" rgba="{cart}"/>
      <body name="pole" pos="0 0 0">
        <joint name="hinge" type="hinge" axis="0 1 0"/>
        <geom name="pole" type="capsule" fromto="0 0 0 0 0 {POLE_LENGTH_M}" size="0.02" rgba="{pole}"/>
      </body>
    </body>
  </worldbody>
</mujoco>"#,
        rail = grey(rail),
        cart = grey(cart),
        pole = grey(pole),
    )
}

/// A render thread: it takes (cart position m, pole angle rad) and answers with the frame,
/// `mono8`, row after row from the top (as the camera kind's synthetic frame).
pub struct Render {
    ask: Sender<(f64, f64)>,
    frames: Receiver<Vec<u8>>,
}

impl Render {
    /// Open MuJoCo's offscreen renderer for frames of `g` on a thread of its own.
    ///
    /// # Errors
    /// One line saying why this machine cannot render (no EGL, no context, a scene MuJoCo
    /// refuses, [`RENDER_ENV`] set to `off`). A failure MuJoCo treats as fatal inside its
    /// context's creation (an OpenGL without framebuffer objects) ends the process, as
    /// MuJoCo's default error handler does.
    pub fn open(g: FrameGeometry) -> Result<Render, String> {
        if std::env::var(RENDER_ENV).as_deref() == Ok("off") {
            return Err(format!("{RENDER_ENV}=off"));
        }
        let (ask, asked) = bounded::<(f64, f64)>(1);
        let (frame_tx, frames) = bounded::<Vec<u8>>(1);
        let (ready_tx, ready) = bounded::<Result<(), String>>(1);
        std::thread::Builder::new()
            .name("camera-render".into())
            .spawn(move || {
                let mut scene = match Scene::new(&g) {
                    Ok(s) => {
                        let _ = ready_tx.send(Ok(()));
                        s
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                for (x, theta) in asked {
                    let Ok(frame) = scene.frame(x, theta) else {
                        return; // the camera sees the channel close and draws instead
                    };
                    if frame_tx.send(frame).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| format!("cannot start the render thread: {e}"))?;
        ready
            .recv_timeout(OPEN_TIMEOUT)
            .map_err(|_| "no OpenGL context within 30 s".to_string())??;
        Ok(Render { ask, frames })
    }

    /// The frame of the cart at `cart_pos_m` with its pole at `theta_rad`; `None` when the
    /// render thread has stopped or is slower than [`FRAME_TIMEOUT`].
    pub fn frame(&self, cart_pos_m: f64, theta_rad: f64) -> Option<Vec<u8>> {
        self.ask.send((cart_pos_m, theta_rad)).ok()?;
        self.frames.recv_timeout(FRAME_TIMEOUT).ok()
    }
}

/// `e` and every error under it, `: `-separated (glutin's own says only "glutin operation
/// failed"; its cause says what failed).
fn causes(e: &dyn std::error::Error) -> String {
    let mut line = e.to_string();
    let mut under = e.source();
    while let Some(cause) = under {
        line.push_str(": ");
        line.push_str(&cause.to_string());
        under = cause.source();
    }
    line
}

/// What the render thread holds: the scene's model, its state, and the renderer.
struct Scene {
    data: MjData<Box<MjModel>>,
    renderer: MjRenderer,
    width: usize,
}

impl Scene {
    fn new(g: &FrameGeometry) -> Result<Scene, String> {
        let model = MjModel::from_xml_string(&scene_xml(g))
            .map_err(|e| format!("MuJoCo refused the camera's scene: {e}"))?;
        let camera = MjvCamera::new_fixed(0);
        let renderer = MjRenderer::builder()
            .width(g.width)
            .height(g.height)
            .camera(camera)
            .build(&model)
            .map_err(|e| format!("MuJoCo cannot render offscreen here: {}", causes(&e)))?;
        Ok(Scene {
            data: MjData::new(Box::new(model)),
            renderer,
            width: g.width as usize,
        })
    }

    /// Render the state and turn it into `mono8` rows from the top (OpenGL reads rows from
    /// the bottom; mujoco-rs gives them from the top already). The scene is grey, so a
    /// pixel's red is its brightness.
    fn frame(&mut self, cart_pos_m: f64, theta_rad: f64) -> Result<Vec<u8>, String> {
        self.data
            .qpos_mut()
            .copy_from_slice(&[cart_pos_m, theta_rad]);
        self.data.forward();
        self.renderer
            .sync_data(&mut self.data)
            .and_then(|()| self.renderer.render())
            .map_err(|e| e.to_string())?;
        let rgb = self.renderer.rgb_flat().ok_or("no colour buffer")?;
        let mut px = Vec::with_capacity(rgb.len() / 3);
        px.extend(rgb.chunks_exact(3).map(|p| p[0]));
        debug_assert_eq!(px.len() % self.width.max(1), 0);
        Ok(px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::nodes::image_estimator::measure;

    /// Open a renderer, or say why not: a machine without EGL skips the comparison, unless
    /// `RATELAB_REQUIRE_RENDER=1` (CI installs Mesa's EGL and sets it) makes that a failure.
    fn open_or_skip(g: FrameGeometry) -> Option<Render> {
        match Render::open(g) {
            Ok(r) => Some(r),
            Err(e) if std::env::var("RATELAB_REQUIRE_RENDER").as_deref() == Ok("1") => {
                panic!("RATELAB_REQUIRE_RENDER=1, and: {e}")
            }
            Err(e) => {
                eprintln!("not compared, this machine cannot render: {e}");
                None
            }
        }
    }

    #[test]
    fn the_estimator_reads_mujoco_s_render_as_it_reads_the_drawing() {
        for (w, h) in [(640, 480), (1024, 768)] {
            let g = FrameGeometry::new(w, h);
            let Some(render) = open_or_skip(g) else {
                return;
            };
            for x in [-1.5, 0.0, 0.7] {
                for theta in [-0.4, -0.05, 0.0, 0.12, 0.3] {
                    let px = render.frame(x, theta).expect("a frame");
                    // Flat greys: each shade exactly, inside its shape (edges are blended).
                    let (rail, cart, pole) = SHADES;
                    for shade in [rail, cart, pole] {
                        assert!(px.contains(&shade), "{w}x{h}: no {shade} in the render");
                    }
                    assert_eq!(px.len(), (w * h) as usize);
                    let drawn = measure(&g.frame(x, theta)).unwrap();
                    let seen = measure(&g.frame_of(px)).unwrap_or_else(|| {
                        panic!("{w}x{h}: no cart or pole in the render at x {x}, θ {theta}")
                    });
                    // Half a pixel for the cart, a hundredth of a radian for the pole.
                    let (dx, dtheta) = (
                        (seen.cart_pos_m - x).abs() * g.scale,
                        (seen.pole_angle_rad - theta).abs(),
                    );
                    assert!(dx <= 0.5, "{w}x{h} x {x} θ {theta}: cart off by {dx} px");
                    assert!(
                        dtheta <= 0.01,
                        "{w}x{h} x {x} θ {theta}: pole off by {dtheta}"
                    );
                    assert!((drawn.pole_angle_rad - theta).abs() <= 0.01);
                }
            }
        }
    }

    #[test]
    fn the_scene_is_the_plant_s_geometry_in_flat_grey() {
        let xml = scene_xml(&FrameGeometry::new(640, 480));
        for needle in [
            r#"offwidth="640" offheight="480""#,
            r#"projection="orthographic""#,
            r#"fromto="0 0 0 0 0 1""#,
            r#"size="0.1 0.05 0.05""#,
            r#"emission="0.7""#,
        ] {
            assert!(xml.contains(needle), "{needle} in {xml}");
        }
        if let Err(e) = MjModel::from_xml_string(&xml) {
            panic!("MuJoCo refused the scene: {e}");
        }
    }
}
