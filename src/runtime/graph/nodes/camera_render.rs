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
//! as it does on a machine without EGL or with [`RENDER_ENV`]`=off`, and in a program that
//! only links the library (never started again with subcommands it may not know).
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
    /// Its last stderr lines, and a receiver that hears when its stderr has ended.
    tail: (Tail, Receiver<()>),
}

impl Render {
    /// Start a renderer for frames of `g`: this program's command line
    /// ([`Program::this_if_set`]) as `render-camera --width W --height H`, then wait for its
    /// [`HELLO`] (at most `OPEN_TIMEOUT`). A program that only links the library is never
    /// started again with arguments it may not know: it draws.
    ///
    /// # Errors
    /// One line saying why this machine cannot render: [`RENDER_ENV`] set to `off`; this
    /// process does not run ratelab's command line; the program cannot be started; it
    /// answered an error (no EGL, no context, a scene MuJoCo refuses), another protocol,
    /// something else (not ratelab's command line) or nothing in time; it exited (how,
    /// and its last stderr lines).
    pub fn open(g: FrameGeometry) -> Result<Render, String> {
        if std::env::var(RENDER_ENV).as_deref() == Ok("off") {
            return Err(format!("{RENDER_ENV}=off"));
        }
        let program = Program::this_if_set().ok_or(
            "this program does not run ratelab's command line (the ratelab binary, \
             ratelab_lab::main_with, the Python package), so it cannot start a renderer",
        )?;
        Render::open_with(&program, g, OPEN_TIMEOUT)
    }

    /// [`Render::open`] with `program` as the renderer, waiting `timeout` for its hello.
    fn open_with(
        program: &Program,
        g: FrameGeometry,
        timeout: std::time::Duration,
    ) -> Result<Render, String> {
        let (width, height) = (g.width.to_string(), g.height.to_string());
        let mut child = program
            .command()
            .arg(SUBCOMMAND)
            .args(["--width", &width, "--height", &height])
            // Whatever it runs draws: a renderer never starts a renderer.
            .env(RENDER_ENV, "off")
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
        let tail = keep_tail(stderr);
        let (ask, asked) = bounded::<(f64, f64)>(1);
        let (frame_tx, frames) = bounded::<Vec<u8>>(1);
        let (ready_tx, ready) = bounded::<Result<(), (String, bool)>>(1);
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
                // A renderer gone or broken: the camera sees the channel close.
                if answered.is_err() || frame_tx.send(frame).is_err() {
                    return;
                }
            }
        };
        let started = std::thread::Builder::new()
            .name("camera-render".into())
            .spawn(talk);
        let mut render = Render {
            ask,
            frames,
            child,
            tail,
        };
        started.map_err(|e| format!("cannot start the render thread: {e}"))?;
        match ready.recv_timeout(timeout) {
            Ok(Ok(())) => Ok(render),
            // Its own reason: its stderr says it again.
            Ok(Err((why, true))) => Err(render.failed(why, false)),
            Ok(Err((why, false))) => Err(render.failed(why, true)),
            Err(_) => {
                let why = format!("no answer within {} s", timeout.as_secs_f64());
                Err(render.failed(why, true))
            }
        }
    }

    /// The frame of the cart at `cart_pos_m` with its pole at `theta_rad`.
    ///
    /// # Errors
    /// One line when the renderer has stopped (how it ended, its last stderr lines) or is
    /// slower than `FRAME_TIMEOUT`; it is ended then, and every later call errs.
    pub fn frame(&mut self, cart_pos_m: f64, theta_rad: f64) -> Result<Vec<u8>, String> {
        use crossbeam_channel::RecvTimeoutError;
        let answer = match self.ask.send((cart_pos_m, theta_rad)) {
            Ok(()) => self.frames.recv_timeout(FRAME_TIMEOUT),
            Err(_) => Err(RecvTimeoutError::Disconnected),
        };
        answer.map_err(|e| {
            let why = match e {
                RecvTimeoutError::Timeout => {
                    format!("no frame within {} s", FRAME_TIMEOUT.as_secs())
                }
                RecvTimeoutError::Disconnected => "the renderer stopped answering".into(),
            };
            self.failed(why, true)
        })
    }

    /// End the renderer after `why` (given half a second to end by itself), and say it in
    /// one line: how the renderer ended, and (`with_stderr`) its last stderr lines.
    fn failed(&mut self, why: String, with_stderr: bool) -> String {
        let status = self.stop(std::time::Duration::from_millis(500));
        // Its stderr ends with it: wait (a little) for the last lines.
        let (tail, ended) = &self.tail;
        let _ = ended.recv_timeout(std::time::Duration::from_secs(1));
        let said = Vec::from(lock_tail(tail).clone()).join(" / ");
        match (status, with_stderr && !said.is_empty()) {
            (Some(status), true) => format!("{why}; it {status}: {said}"),
            (Some(status), false) => format!("{why}; it {status}"),
            (None, _) => why,
        }
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

/// How much of a line that is not the renderer's the camera quotes, characters.
const QUOTED_CHARS: usize = 200;

/// Read the renderer's first line: `Ok` for [`HELLO`]` ok`, else why not, and whether the
/// renderer said why itself (` error: WHY`).
fn read_hello(from: &mut impl BufRead) -> Result<(), (String, bool)> {
    let mut line = Vec::new();
    from.take(MAX_HELLO_BYTES)
        .read_until(b'\n', &mut line)
        .map_err(|e| (format!("the renderer's pipe: {e}"), false))?;
    let line = String::from_utf8_lossy(&line);
    let line = ratelab_core::text::printable(line.trim_end());
    let quoted = || {
        let mut q: String = line.chars().take(QUOTED_CHARS).collect();
        if q.len() < line.len() {
            q.push('…');
        }
        q
    };
    let Some(rest) = line.strip_prefix(HELLO).and_then(|r| r.strip_prefix(' ')) else {
        let why = if line.is_empty() {
            "the renderer said nothing".into()
        } else if line.starts_with("ratelab-render ") {
            format!(
                "the renderer speaks another protocol: it said '{}'",
                quoted()
            )
        } else {
            format!("not ratelab's renderer: it said '{}'", quoted())
        };
        return Err((why, false));
    };
    match rest.strip_prefix("error: ") {
        _ if rest == "ok" => Ok(()),
        Some(why) if !why.trim().is_empty() => Err((why.to_string(), true)),
        _ => Err((format!("the renderer said '{}'", quoted()), false)),
    }
}

/// The renderer's last stderr lines, as [`STDERR_TAIL`] bounds them.
type Tail = Arc<Mutex<VecDeque<String>>>;

/// Read `stderr` to its end on a thread of its own (so that a renderer that talks is never
/// blocked on a full pipe), keeping its last lines, each cut to its bound as it is read;
/// the receiver hears when it has ended.
fn keep_tail(stderr: impl Read + Send + 'static) -> (Tail, Receiver<()>) {
    let tail: Tail = Arc::default();
    let keep = tail.clone();
    let (done_tx, done) = bounded::<()>(1);
    let _ = std::thread::Builder::new()
        .name("camera-render-stderr".into())
        .spawn(move || {
            let _done = done_tx; // dropped at the end: the receiver hears it
            let (lines, width) = STDERR_TAIL;
            let mut from = BufReader::new(stderr);
            let mut line = Vec::with_capacity(width);
            while let Ok(true) = ratelab_core::input::read_line_bounded(&mut from, width, &mut line)
            {
                let text = String::from_utf8_lossy(&line);
                let text = ratelab_core::text::printable(text.trim()).to_string();
                if text.is_empty() {
                    continue;
                }
                let mut tail = lock_tail(&keep);
                if tail.len() == lines {
                    tail.pop_front();
                }
                tail.push_back(text);
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
            // One line (MuJoCo's errors may span several).
            let why = why.lines().map(str::trim).collect::<Vec<_>>().join(" / ");
            let why = ratelab_core::text::printable(&why).into_owned();
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
/// frames. SIGINT is ignored (a terminal's Ctrl-C is the camera's run's to handle; it ends
/// the renderer by closing the pipe); SIGTERM ends it.
///
/// # Errors
/// As [`serve`]'s; stdout that cannot be moved.
pub fn serve_stdio(width: u32, height: u32) -> Result<(), String> {
    use std::os::fd::FromRawFd;
    // A terminal's Ctrl-C reaches the whole process group: the camera's run handles it, and
    // ends its renderer through the pipe. SIGTERM still ends it at once.
    // SAFETY: setting a signal's disposition to "ignore" installs no handler.
    unsafe { libc::signal(libc::SIGINT, libc::SIG_IGN) };
    // SAFETY: dup and dup2 on this process's own standard descriptors, before anything is
    // written to stdout; the copy is owned by the File and closed with it.
    let frames = unsafe {
        // Close-on-exec: nothing the driver may start holds the frames' pipe open.
        let copy = libc::fcntl(libc::STDOUT_FILENO, libc::F_DUPFD_CLOEXEC, 3);
        if copy < 0 {
            let e = std::io::Error::last_os_error();
            return Err(format!("cannot copy stdout: {e}"));
        }
        let frames = std::fs::File::from_raw_fd(copy);
        if libc::dup2(libc::STDERR_FILENO, libc::STDOUT_FILENO) < 0 {
            let e = std::io::Error::last_os_error();
            return Err(format!("cannot point stdout at stderr: {e}"));
        }
        frames
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

/// What the renderer's process holds: the scene's model, its state, and MuJoCo's renderer.
struct Scene {
    data: MjData<Box<MjModel>>,
    renderer: MjRenderer,
    /// The frame's pixels, `width × height`.
    pixels: usize,
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
            pixels: g.width as usize * g.height as usize,
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
        if rgb.len() != 3 * self.pixels {
            // A driver that rendered another size: refused, never shifted into the next.
            let got = rgb.len() / 3;
            return Err(format!("a frame of {got} pixels, not {}", self.pixels));
        }
        let mut px = Vec::with_capacity(self.pixels);
        px.extend(rgb.chunks_exact(3).map(|p| p[0]));
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
        let draw = |x: f64, theta: f64| Ok(g.frame(x, theta).data.as_slice().to_vec());
        let mut from = Vec::new();
        for (x, theta) in [(0.5f64, 0.1f64), (-1.0, -0.2)] {
            from.extend(x.to_le_bytes());
            from.extend(theta.to_le_bytes());
        }
        from.extend([1, 2, 3]); // a request cut short ends the stream
        let mut to = Vec::new();
        answer(draw, &from[..], &mut to).unwrap();
        let mut want = g.frame(0.5, 0.1).data.as_slice().to_vec();
        want.extend(g.frame(-1.0, -0.2).data.as_slice().iter());
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
        let other = |why: &str| Err((why.to_string(), false));
        assert_eq!(hello("ratelab-render 1 ok\n"), Ok(()));
        // Its own reason, which its stderr says again.
        assert_eq!(
            hello("ratelab-render 1 error: no EGL device\n"),
            Err(("no EGL device".into(), true))
        );
        assert_eq!(hello(""), other("the renderer said nothing"));
        assert_eq!(
            hello("running 0 tests\n"),
            other("not ratelab's renderer: it said 'running 0 tests'")
        );
        assert_eq!(
            hello("ratelab-render 12 ok\n"),
            other("the renderer speaks another protocol: it said 'ratelab-render 12 ok'")
        );
        assert_eq!(
            hello("ratelab-render 1\n"),
            other("the renderer speaks another protocol: it said 'ratelab-render 1'")
        );
        assert_eq!(
            hello("ratelab-render 1 error: \n"),
            other("the renderer said 'ratelab-render 1 error:'")
        );
        // A line without an end is read no further than its bound, and quoted shorter.
        let endless = "x".repeat(1 << 20);
        let (e, _) = hello(&endless).unwrap_err();
        assert!(e.chars().count() < QUOTED_CHARS + 60, "{}", e.len());
        assert!(e.ends_with("…'"), "{e}");
    }

    #[test]
    fn a_renderer_serves_frames_until_it_stops_and_then_the_camera_hears_none() {
        let frame = SMALL.0 * SMALL.1;
        // Hello, then one request read and one frame of zeros answered, then gone.
        let script = format!(
            "printf 'ratelab-render 1 ok\\n'; dd bs=16 count=1 status=none of=/dev/null; \
             head -c {frame} /dev/zero"
        );
        let mut render = open(&script, 10_000).unwrap();
        assert_eq!(render.frame(0.0, 0.0), Ok(vec![0; frame as usize]));
        let e = render.frame(0.0, 0.0).unwrap_err();
        assert!(e.starts_with("the renderer stopped answering"), "{e}");
        assert!(e.contains("exited (exit status: 0)"), "{e}");
        // It is ended: every later frame says so at once.
        assert!(render.frame(0.0, 0.0).is_err());
        // One that stalls is given up on after its time, and ended.
        let script = "printf 'ratelab-render 1 ok\\n'; exec sleep 60";
        let mut render = open(script, 10_000).unwrap();
        let e = render.frame(0.0, 0.0).unwrap_err();
        assert!(e.starts_with("no frame within 5 s"), "{e}");
    }

    #[test]
    fn a_renderer_that_cannot_render_is_said_in_one_line_with_why() {
        // Its reason, and its exit: not its stderr, which says the same again.
        let script =
            "echo 'ratelab-render 1 error: no EGL device'; echo 'error: no EGL device' >&2";
        let e = open(script, 10_000).unwrap_err();
        assert_eq!(e, "no EGL device; it exited (exit status: 0)");
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
    fn the_stderr_tail_keeps_the_last_lines_each_cut_to_its_bound() {
        let (lines, width) = STDERR_TAIL;
        let long = "y".repeat(10 * width);
        let text = format!("one\ntwo\n\nthree\n{long}\nfour\x1b[31m\nfive");
        let (tail, done) = keep_tail(std::io::Cursor::new(text.into_bytes()));
        let ended = done.recv_timeout(Duration::from_secs(10));
        assert_eq!(
            ended,
            Err(crossbeam_channel::RecvTimeoutError::Disconnected)
        );
        let kept = Vec::from(lock_tail(&tail).clone());
        assert_eq!(kept.len(), lines);
        assert_eq!(kept[0], "three");
        assert_eq!(kept[1], "y".repeat(width));
        assert!(!kept[2].contains('\x1b'), "{kept:?}"); // printable
        assert_eq!(kept[3], "five");
    }

    #[test]
    fn a_program_that_only_links_the_library_is_not_started_again_and_draws() {
        // No test here sets this test binary as ratelab's command line, and none must: it
        // is not one (libtest would read `render-camera` as a filter).
        assert_eq!(Program::this_if_set(), None);
        let e = Render::open(FrameGeometry::new(SMALL.0, SMALL.1)).unwrap_err();
        assert!(e.contains("does not run ratelab's command line"), "{e}");
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
