//! MuJoCo's offscreen render of the cartpole, for the **camera** kind's `mujoco = 1`: the
//! same rail, cart and pole as `assets/cartpole.xml`, seen through an orthographic camera
//! placed so that a metre spans exactly the pixels the synthetic frame gives it
//! ([`FrameGeometry`]), flat-shaded in the synthetic frame's [`SHADES`] on black. So the
//! **image_estimator** kind reads a rendered frame as it reads a drawn one.
//!
//! Rendering needs an OpenGL context: mujoco-rs opens one offscreen through EGL (a GPU's, or
//! Mesa's software renderer, llvmpipe). That stack (EGL, a GL driver, a JIT compiler,
//! MuJoCo's `mjr_*`) is C code of the machine's, so it runs in a **process of its own**:
//! [`Render::open`] starts this program's command line as `ratelab render-camera`
//! ([`SUBCOMMAND`], [`serve`]), as dora-rs runs a node as its own program. A renderer that
//! crashes, hangs or corrupts its memory costs the camera its rendered frames, never the
//! run: the camera says why in one line of its log and draws its synthetic frame instead,
//! as it does on a machine without EGL or with [`RENDER_ENV`]`=off`.
//!
//! The pipe between them carries fixed-size records, one request and one answer a frame:
//! - **camera → renderer**: the cart's position (m) and the pole's angle (rad), two
//!   little-endian `f64`s;
//! - **renderer → camera**: first one line, [`HELLO`] then ` ok` or ` error: WHY`; then, a
//!   request at a time, the frame, `width × height` bytes of `mono8`, rows from the top.
//!
//! A rendered frame is the same for the same state on one machine and driver, not across
//! machines (rasterizers differ in their last bits): a run with `mujoco = 1` replays on the
//! machine that made it, and only the synthetic frame is byte-identical everywhere.

use super::frame::{FrameGeometry, CART_HALF_M, POLE_LENGTH_M, SHADES};
use crate::program::Program;
use crossbeam_channel::{bounded, Receiver, Sender};
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::process::Stdio;
use std::sync::{Arc, Mutex};

/// How long the camera waits for a frame before it draws the synthetic one instead (a
/// render of a 4096 × 4096 frame in software takes well under a second).
const FRAME_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

/// How long opening the renderer may take before the camera draws instead (the process's
/// start, EGL's, MuJoCo's context: well under a second in software).
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

/// The subcommand of ratelab's command line that serves frames ([`serve`]); hidden from
/// its help, as it is a camera's and not a person's.
pub const SUBCOMMAND: &str = "render-camera";

/// The first words of the renderer's first line: which protocol it speaks.
pub const HELLO: &str = "ratelab-render 1";

/// The longest first line the camera reads from its renderer, bytes.
const MAX_HELLO_BYTES: u64 = 4096;

/// How many of the renderer's last stderr lines the camera keeps, to say why it stopped, and
/// how long each may be (bytes; longer lines are cut).
const STDERR_TAIL: (usize, usize) = (4, 300);

/// A renderer in a process of its own: it takes (cart position m, pole angle rad) and
/// answers with the frame, `mono8`, row after row from the top (as the camera kind's
/// synthetic frame). Dropping it ends the process.
#[derive(Debug)]
pub struct Render {
    ask: Sender<(f64, f64)>,
    frames: Receiver<Vec<u8>>,
    child: std::process::Child,
}

impl Render {
    /// Start a renderer for frames of `g`: this program's command line
    /// ([`Program::this`]) as `render-camera --width W --height H`, then wait for its
    /// [`HELLO`] (at most [`OPEN_TIMEOUT`]).
    ///
    /// # Errors
    /// One line saying why this machine cannot render: [`RENDER_ENV`] set to `off`; the
    /// program cannot be started; it answered no [`HELLO`] (not ratelab's command line), an
    /// error (no EGL, no context, a scene MuJoCo refuses), or nothing in time; it exited
    /// (its last stderr lines follow).
    pub fn open(g: FrameGeometry) -> Result<Render, String> {
        if std::env::var(RENDER_ENV).as_deref() == Ok("off") {
            return Err(format!("{RENDER_ENV}=off"));
        }
        let program = Program::this().map_err(|e| format!("cannot find this program: {e}"))?;
        Render::open_with(&program, g, OPEN_TIMEOUT)
    }

    /// [`Render::open`] with `program` as the renderer, waiting `timeout` for its hello.
    fn open_with(
        program: &Program,
        g: FrameGeometry,
        timeout: std::time::Duration,
    ) -> Result<Render, String> {
        let mut child = program
            .command()
            .arg(SUBCOMMAND)
            .args([
                "--width",
                &g.width.to_string(),
                "--height",
                &g.height.to_string(),
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", program.path.display()))?;
        let (Some(stdin), Some(stdout), Some(stderr)) =
            (child.stdin.take(), child.stdout.take(), child.stderr.take())
        else {
            let _ = child.kill();
            let _ = child.wait();
            return Err("the renderer's pipes were not opened".into());
        };
        let (tail, tail_done) = keep_tail(stderr);
        let (ask, asked) = bounded::<(f64, f64)>(1);
        let (frame_tx, frames) = bounded::<Vec<u8>>(1);
        let (ready_tx, ready) = bounded::<Result<(), String>>(1);
        let frame_bytes = g.width as usize * g.height as usize;
        let talk = move || {
            let mut from = BufReader::new(stdout);
            let hello = read_hello(&mut from);
            let ok = hello.is_ok();
            let _ = ready_tx.send(hello);
            if !ok {
                return;
            }
            let mut to = stdin;
            for (x, theta) in asked {
                let request = [x.to_le_bytes(), theta.to_le_bytes()];
                let mut frame = vec![0u8; frame_bytes];
                let answered = to
                    .write_all(request.as_flattened())
                    .and_then(|()| to.flush())
                    .and_then(|()| from.read_exact(&mut frame));
                // A renderer gone or broken: the camera sees the channel close and draws.
                if answered.is_err() || frame_tx.send(frame).is_err() {
                    return;
                }
            }
        };
        let started = std::thread::Builder::new()
            .name("camera-render".into())
            .spawn(talk);
        let mut render = Render { ask, frames, child };
        started.map_err(|e| format!("cannot start the render thread: {e}"))?;
        let why = match ready.recv_timeout(timeout) {
            Ok(Ok(())) => return Ok(render),
            Ok(Err(why)) => why,
            Err(_) => format!("no answer within {} s", timeout.as_secs_f64()),
        };
        let status = render.stop(std::time::Duration::from_millis(500));
        // Its stderr ends with it: wait (a little) for the last lines.
        let _ = tail_done.recv_timeout(std::time::Duration::from_secs(1));
        let said = Vec::from(lock_tail(&tail).clone()).join(" / ");
        Err(match (status, said.is_empty()) {
            (Some(status), false) => format!("{why}; the renderer {status}: {said}"),
            (Some(status), true) => format!("{why}; the renderer {status}"),
            (None, _) => why,
        })
    }

    /// The frame of the cart at `cart_pos_m` with its pole at `theta_rad`; `None` when the
    /// renderer has stopped or is slower than [`FRAME_TIMEOUT`].
    pub fn frame(&self, cart_pos_m: f64, theta_rad: f64) -> Option<Vec<u8>> {
        self.ask.send((cart_pos_m, theta_rad)).ok()?;
        self.frames.recv_timeout(FRAME_TIMEOUT).ok()
    }

    /// End the renderer's process, given `grace` to end by itself first, and reap it; how
    /// it ended, if it ended by itself.
    fn stop(&mut self, grace: std::time::Duration) -> Option<String> {
        let until = std::time::Instant::now() + grace;
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) => return Some(format!("exited ({status})")),
                Ok(None) if std::time::Instant::now() < until => {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                _ => break,
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        None
    }
}

impl Drop for Render {
    fn drop(&mut self) {
        self.stop(std::time::Duration::ZERO);
    }
}

/// Read the renderer's first line: `Ok` for [`HELLO`]` ok`, else why not.
fn read_hello(from: &mut impl BufRead) -> Result<(), String> {
    let mut line = Vec::new();
    from.take(MAX_HELLO_BYTES)
        .read_until(b'\n', &mut line)
        .map_err(|e| format!("the renderer's pipe: {e}"))?;
    let line = String::from_utf8_lossy(&line);
    let line = crate::text::printable(line.trim_end());
    match line.strip_prefix(HELLO) {
        Some(" ok") => Ok(()),
        Some(rest) => Err(rest.trim_start().trim_start_matches("error: ").to_string()),
        None if line.is_empty() => Err("the renderer said nothing".into()),
        None => Err(format!("not ratelab's renderer: it said '{line}'")),
    }
}

/// The renderer's last stderr lines, as [`STDERR_TAIL`] bounds them.
type Tail = Arc<Mutex<VecDeque<String>>>;

/// Read `stderr` to its end on a thread of its own (so that a renderer that talks is never
/// blocked on a full pipe), keeping its last lines; the receiver hears when it has ended.
fn keep_tail(stderr: impl Read + Send + 'static) -> (Tail, Receiver<()>) {
    let tail: Tail = Arc::default();
    let keep = tail.clone();
    let (done_tx, done) = bounded::<()>(1);
    let _ = std::thread::Builder::new()
        .name("camera-render-stderr".into())
        .spawn(move || {
            let _done = done_tx; // dropped at the end: the receiver hears it
            let (lines, width) = STDERR_TAIL;
            for line in BufReader::new(stderr).split(b'\n') {
                let Ok(line) = line else { return };
                let line = String::from_utf8_lossy(&line[..line.len().min(width)]);
                let line = crate::text::printable(line.trim()).to_string();
                if line.is_empty() {
                    continue;
                }
                let mut tail = lock_tail(&keep);
                if tail.len() == lines {
                    tail.pop_front();
                }
                tail.push_back(line);
            }
        });
    (tail, done)
}

fn lock_tail(tail: &Tail) -> std::sync::MutexGuard<'_, VecDeque<String>> {
    tail.lock().unwrap_or_else(|e| e.into_inner())
}

/// The renderer's side, `ratelab render-camera`: open MuJoCo's offscreen renderer for
/// frames of `width × height` px, say [`HELLO`] on `to` (` ok`, or ` error: WHY`), then
/// answer each request read from `from` with its frame ([`answer`]), until `from` ends.
///
/// # Errors
/// The line already said on `to` when the renderer cannot open; [`answer`]'s. MuJoCo ends
/// the process itself on what it treats as fatal (an OpenGL without framebuffer objects),
/// as its default error handler does.
pub fn serve(width: u32, height: u32, from: impl Read, mut to: impl Write) -> Result<(), String> {
    let g = FrameGeometry::new(width, height);
    let mut scene = match Scene::new(&g) {
        Ok(scene) => scene,
        Err(why) => {
            let _ = writeln!(to, "{HELLO} error: {why}").and_then(|()| to.flush());
            return Err(why);
        }
    };
    writeln!(to, "{HELLO} ok")
        .and_then(|()| to.flush())
        .map_err(|e| format!("the camera's pipe: {e}"))?;
    answer(|x, theta| scene.frame(x, theta), from, to)
}

/// Answer each request read from `from` (two little-endian `f64`s: the cart's position m
/// and the pole's angle rad) with `render`'s frame for it on `to`, until `from` ends (a
/// request cut short ends it too).
///
/// # Errors
/// A request that is not two finite numbers; `render`'s error; a pipe that breaks.
pub fn answer(
    mut render: impl FnMut(f64, f64) -> Result<Vec<u8>, String>,
    mut from: impl Read,
    mut to: impl Write,
) -> Result<(), String> {
    let pipe = |e: std::io::Error| format!("the camera's pipe: {e}");
    let mut request = [[0u8; 8]; 2];
    loop {
        match from.read_exact(request.as_flattened_mut()) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(pipe(e)),
        }
        let [x, theta] = request.map(f64::from_le_bytes);
        if !(x.is_finite() && theta.is_finite()) {
            return Err(format!("a request that is not a state: x {x}, θ {theta}"));
        }
        let frame = render(x, theta)?;
        to.write_all(&frame)
            .and_then(|()| to.flush())
            .map_err(pipe)?;
    }
}

/// [`serve`] on this process's stdin and stdout, as `ratelab render-camera` runs it. The
/// frames go out on a copy of stdout, and stdout itself is pointed at stderr, so that
/// whatever a library prints (MuJoCo's warnings are printed) can never fall between two
/// frames.
///
/// # Errors
/// As [`serve`]'s; stdout that cannot be moved.
pub fn serve_stdio(width: u32, height: u32) -> Result<(), String> {
    use std::os::fd::FromRawFd;
    // SAFETY: dup and dup2 on this process's own standard descriptors, before anything is
    // written to stdout; the copy is owned by the File and closed with it.
    let frames = unsafe {
        let copy = libc::dup(libc::STDOUT_FILENO);
        if copy < 0 || libc::dup2(libc::STDERR_FILENO, libc::STDOUT_FILENO) < 0 {
            let e = std::io::Error::last_os_error();
            return Err(format!("cannot move stdout: {e}"));
        }
        std::fs::File::from_raw_fd(copy)
    };
    serve(
        width,
        height,
        std::io::stdin().lock(),
        BufWriter::new(frames),
    )
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
    use std::time::Duration;

    // Rendered frames against drawn ones, through `ratelab render-camera`, are checked where
    // the binary is: tests/it/graphs.rs. Here: the pipe's two ends, with stand-ins.

    /// A stand-in renderer: a shell script in place of ratelab's command line.
    fn shell(script: &str) -> Program {
        Program {
            path: "/bin/sh".into(),
            args: vec!["-c".into(), script.into()],
        }
    }

    const SMALL: (u32, u32) = (16, 16);

    fn open(script: &str, timeout_ms: u64) -> Result<Render, String> {
        let g = FrameGeometry::new(SMALL.0, SMALL.1);
        Render::open_with(&shell(script), g, Duration::from_millis(timeout_ms))
    }

    #[test]
    fn answer_serves_a_frame_a_request_until_the_requests_end() {
        let g = FrameGeometry::new(32, 24);
        let draw = |x: f64, theta: f64| Ok(g.frame(x, theta).data.0.to_vec());
        let mut from = Vec::new();
        for (x, theta) in [(0.5f64, 0.1f64), (-1.0, -0.2)] {
            from.extend(x.to_le_bytes());
            from.extend(theta.to_le_bytes());
        }
        from.extend([1, 2, 3]); // a request cut short ends the stream
        let mut to = Vec::new();
        answer(draw, &from[..], &mut to).unwrap();
        let mut want = g.frame(0.5, 0.1).data.0.to_vec();
        want.extend(g.frame(-1.0, -0.2).data.0.iter());
        assert_eq!(to, want);
        // A request that is not a state is refused, and nothing is answered to it.
        let nan = [f64::NAN.to_le_bytes(), 0.0f64.to_le_bytes()];
        let mut to = Vec::new();
        let e = answer(draw, nan.as_flattened(), &mut to).unwrap_err();
        assert!(e.contains("not a state"), "{e}");
        assert!(to.is_empty());
        // A renderer's error ends it with that error.
        let broken = |_: f64, _: f64| Err::<Vec<u8>, _>("lost the context".to_string());
        let zero = [0.0f64.to_le_bytes(), 0.0f64.to_le_bytes()];
        assert_eq!(
            answer(broken, zero.as_flattened(), Vec::new()),
            Err("lost the context".into())
        );
    }

    #[test]
    fn the_hello_says_ok_or_why_not_and_anything_else_is_not_the_renderer() {
        let hello = |line: &str| read_hello(&mut line.as_bytes());
        assert_eq!(hello("ratelab-render 1 ok\n"), Ok(()));
        assert_eq!(
            hello("ratelab-render 1 error: no EGL device\n"),
            Err("no EGL device".into())
        );
        assert_eq!(hello(""), Err("the renderer said nothing".into()));
        let e = hello("running 0 tests\n").unwrap_err();
        assert_eq!(e, "not ratelab's renderer: it said 'running 0 tests'");
        // A line without an end is read no further than its bound.
        let endless = "x".repeat(1 << 20);
        let e = hello(&endless).unwrap_err();
        assert!(e.len() < MAX_HELLO_BYTES as usize + 100, "{}", e.len());
    }

    #[test]
    fn a_renderer_serves_frames_until_it_stops_and_then_the_camera_hears_none() {
        let frame = SMALL.0 * SMALL.1;
        // Hello, then one request read and one frame of zeros answered, then gone.
        let script = format!(
            "printf 'ratelab-render 1 ok\\n'; dd bs=16 count=1 status=none of=/dev/null; \
             head -c {frame} /dev/zero"
        );
        let render = open(&script, 10_000).unwrap();
        assert_eq!(render.frame(0.0, 0.0), Some(vec![0; frame as usize]));
        assert_eq!(render.frame(0.0, 0.0), None);
    }

    #[test]
    fn a_renderer_that_cannot_render_is_said_in_one_line_with_why() {
        let e = open("echo 'ratelab-render 1 error: no EGL device'", 10_000).unwrap_err();
        assert!(e.starts_with("no EGL device"), "{e}");
        // Another program (here a test binary's libtest) is not taken for the renderer.
        let e = open("echo 'running 0 tests'", 10_000).unwrap_err();
        assert!(
            e.starts_with("not ratelab's renderer: it said 'running 0 tests'"),
            "{e}"
        );
        // One that dies says how, with its last words.
        let e = open("echo 'MuJoCo: fatal' >&2; exit 3", 10_000).unwrap_err();
        assert!(e.contains("the renderer said nothing"), "{e}");
        assert!(e.contains("exit status: 3"), "{e}");
        assert!(e.ends_with("MuJoCo: fatal"), "{e}");
        // One that never answers is given up on, and ended.
        let started = std::time::Instant::now();
        let e = open("exec sleep 60", 300).unwrap_err();
        assert!(e.contains("no answer within 0.3 s"), "{e}");
        assert!(started.elapsed() < Duration::from_secs(30));
        // A program that is not there.
        let missing = Program::from(std::path::PathBuf::from("/nonexistent/ratelab"));
        let g = FrameGeometry::new(SMALL.0, SMALL.1);
        let e = Render::open_with(&missing, g, Duration::from_secs(1))
            .err()
            .unwrap();
        assert!(e.starts_with("cannot start /nonexistent/ratelab"), "{e}");
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
