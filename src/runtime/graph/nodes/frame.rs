//! Where a camera's frame shows the world, and the synthetic drawing of it: the geometry
//! ([`FrameGeometry`]: metres to pixels, the hinge's row), the cartpole's sizes and the
//! shades of the rail, the cart and the pole. The **camera** kind draws with it, MuJoCo's
//! render ([`super::camera_render`]) is placed by it, and the **image_estimator** kind
//! reads frames back through it.

use ratelab_core::msg::ImageMsg;
use ratelab_core::pixels::ImageData;

/// Where a frame of `width` × `height` draws the world: the rail along the bottom, the
/// hinge on it, metres to pixels at one scale both ways (6 m of rail across, the 1 m pole
/// and the cart fit above it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameGeometry {
    /// Columns, px.
    pub width: u32,
    /// Rows, px.
    pub height: u32,
    /// Pixels per metre.
    pub scale: f64,
    /// The hinge's row (the cart's centre), px from the top.
    pub hinge_row: f64,
}

/// The pole's length (`assets/cartpole.xml`), m.
pub const POLE_LENGTH_M: f64 = 1.0;
/// The cart's half width and half height, m.
pub const CART_HALF_M: (f64, f64) = (0.1, 0.05);
/// The pole's radius as drawn, m (at least a pixel).
const POLE_RADIUS_M: f64 = 0.02;
/// Brightness of the rail, the cart and the pole (the background is 0).
pub const SHADES: (u8, u8, u8) = (64, 128, 255);

impl FrameGeometry {
    /// The geometry of a `width` × `height` frame.
    pub fn new(width: u32, height: u32) -> FrameGeometry {
        let (w, h) = (f64::from(width), f64::from(height));
        FrameGeometry {
            width,
            height,
            scale: (w / 6.0).min(0.7 * h / (POLE_LENGTH_M + 2.0 * CART_HALF_M.1)),
            hinge_row: 0.85 * h,
        }
    }

    /// The pole's radius as drawn, px (at least one).
    pub fn pole_radius_px(&self) -> f64 {
        (POLE_RADIUS_M * self.scale).max(1.0)
    }

    /// The rows the cart's box covers, px from the top (end excluded): its height, and in a
    /// small frame at least the pole's radius and two rows more below the hinge (so that
    /// the rows under the pole's round end show the cart alone).
    pub fn cart_rows(&self) -> std::ops::Range<usize> {
        let half = (CART_HALF_M.1 * self.scale).max(self.pole_radius_px() + 2.0);
        let lo = (self.hinge_row - half).round().max(0.0) as usize;
        let hi = ((self.hinge_row + half).round().max(0.0) as usize).min(self.height as usize);
        lo..hi
    }

    /// The column of world position `x_m`, px (the rail's centre mid-frame).
    pub fn column(&self, x_m: f64) -> f64 {
        f64::from(self.width) / 2.0 + x_m * self.scale
    }

    /// A frame of the cart at `cart_pos_m` with its pole at `theta_rad` (from upright,
    /// positive toward +x), `mono8`, row after row.
    pub fn draw(&self, cart_pos_m: f64, theta_rad: f64) -> Vec<u8> {
        let mut px = vec![0u8; self.byte_len()];
        self.draw_into(&mut px, cart_pos_m, theta_rad);
        px
    }

    /// The bytes of a frame, `mono8`: width × height.
    pub fn byte_len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// [`FrameGeometry::draw`] into `px`, which must be [`FrameGeometry::byte_len`] long
    /// with every byte 0 (a buffer the frame's topic lent,
    /// [`ratelab_core::msg::AnyTopic::loan_pixels`]); nothing is drawn into one of another
    /// length (a caller's mistake: a debug build stops on it).
    pub fn draw_into(&self, px: &mut [u8], cart_pos_m: f64, theta_rad: f64) {
        let (w, h) = (self.width as usize, self.height as usize);
        debug_assert_eq!(px.len(), w * h, "a frame's buffer of another length");
        if px.len() != w * h {
            return;
        }
        let s = self.scale;
        let (rail, cart, pole) = SHADES;
        // The rail: a row under the cart.
        let rail_row = self.cart_rows().end + 1;
        if rail_row < h {
            px[rail_row * w..(rail_row + 1) * w].fill(rail);
        }
        // The cart: a box around the hinge.
        let hx = self.column(cart_pos_m);
        let span = |c: f64, half: f64, n: usize| {
            let lo = (c - half).round().max(0.0) as usize;
            let hi = ((c + half).round().max(0.0) as usize).min(n);
            lo..hi
        };
        for r in self.cart_rows() {
            for c in span(hx, CART_HALF_M.0 * s, w) {
                px[r * w + c] = cart;
            }
        }
        // The pole: every pixel within its radius of the segment hinge → tip, its edge
        // shaded by how far in it is (anti-aliased: a reader finds it to a fraction of a
        // pixel).
        let (sin, cos) = theta_rad.sin_cos();
        let (tx, ty) = (
            hx + POLE_LENGTH_M * s * sin,
            self.hinge_row - POLE_LENGTH_M * s * cos,
        );
        let radius = self.pole_radius_px();
        let (x0, x1) = (hx.min(tx) - radius - 1.0, hx.max(tx) + radius + 1.0);
        let (y0, y1) = (
            self.hinge_row.min(ty) - radius - 1.0,
            self.hinge_row.max(ty) + radius + 1.0,
        );
        let (dx, dy) = (tx - hx, ty - self.hinge_row);
        let len2 = (dx * dx + dy * dy).max(f64::MIN_POSITIVE);
        for r in span((y0 + y1) / 2.0, (y1 - y0) / 2.0, h) {
            for c in span((x0 + x1) / 2.0, (x1 - x0) / 2.0, w) {
                let (cx, cy) = (c as f64 + 0.5, r as f64 + 0.5);
                let t = (((cx - hx) * dx + (cy - self.hinge_row) * dy) / len2).clamp(0.0, 1.0);
                let (ex, ey) = (cx - hx - t * dx, cy - self.hinge_row - t * dy);
                let d = (ex * ex + ey * ey).sqrt();
                let cover = (radius + 0.5 - d).clamp(0.0, 1.0);
                let v = (f64::from(pole) * cover).round() as u8;
                let p = &mut px[r * w + c];
                *p = (*p).max(v);
            }
        }
    }

    /// The frame as a message.
    pub fn frame(&self, cart_pos_m: f64, theta_rad: f64) -> ImageMsg {
        self.frame_of(self.draw(cart_pos_m, theta_rad))
    }

    /// A frame of this size holding `px` (`mono8`, row after row from the top).
    pub fn frame_of(&self, px: impl Into<ImageData>) -> ImageMsg {
        ImageMsg {
            height: self.height,
            width: self.width,
            encoding: "mono8".into(),
            step: self.width,
            data: px.into(),
        }
    }
}
