//! The **image_estimator** kind: reads the newest camera frame and measures the cart's
//! position and the pole's angle from its pixels (what the **camera** kind draws:
//! [`super::frame::FrameGeometry`]), publishing a `position` for an estimator to turn into
//! a state. The cart is found from its lower half (which the pole never covers), the pole
//! from the brightness above the cart weighted by how much of each pixel it covers: the
//! angle to a fraction of a pixel at the pole's tip. A frame with no pole in it publishes
//! nothing. Its message carries the frame's origin stamp (sense→act latency counts from
//! when the camera looked).

use super::frame::{FrameGeometry, SHADES};
use crate::graph::kind::{Code, KindDef, Params};
use ratelab_core::msg::{ImageMsg, PositionMsg};
use ratelab_core::node::NodeState;
use ratelab_core::ports::RustNode;
use ratelab_core::time::Nanos;

/// The kind: `image` in, `position` out.
pub fn def() -> KindDef {
    KindDef {
        doc: "measures the cart's position and the pole's angle from a camera's frame",
        code: Code::BuiltIn,
        params: Params::Numbers(&[]),
        ..KindDef::of("image_estimator", |_| Ok(ImageEstimator))
    }
}

/// The cart's position (m) and the pole's angle (rad) in a frame the camera kind drew, if
/// both are in it: `None` for a frame that is not whole `mono8`, or shows no cart or pole.
pub fn measure(img: &ImageMsg) -> Option<PositionMsg> {
    if img.encoding != "mono8" || !img.is_consistent() || img.width == 0 || img.height == 0 {
        return None;
    }
    let g = FrameGeometry::new(img.width, img.height);
    let (w, step) = (img.width as usize, img.step as usize);
    let px = img.data.as_slice();
    let row = |r: usize| &px[r * step..r * step + w];
    let (_, cart, _) = SHADES;
    // The cart: the columns of its shade in the rows of its lower half that the pole's
    // round end does not reach.
    let rows = g.cart_rows();
    // (A row's centre further below the hinge than the pole's radius and a half pixel.)
    let below_pole = (g.hinge_row + g.pole_radius_px()).floor() as usize + 1;
    let (mut sum, mut n) = (0.0, 0.0);
    for r in below_pole.max(rows.start)..rows.end {
        for (c, v) in row(r).iter().enumerate() {
            if *v == cart {
                sum += c as f64 + 0.5;
                n += 1.0;
            }
        }
    }
    if n == 0.0 {
        return None;
    }
    let hx = sum / n;
    // The pole: the brightness above the cart's top, each pixel weighted by it; its angle
    // from upright is the direction of those pixels' principal axis (the hinge's column,
    // found from a box of whole pixels, is off by up to half of one: the axis is not).
    let (mut w, mut su, mut sv) = (0.0, 0.0, 0.0);
    let (mut suu, mut svv, mut suv) = (0.0, 0.0, 0.0);
    for r in 0..rows.start {
        for (c, v) in row(r).iter().enumerate() {
            if *v > 0 {
                let wv = f64::from(*v);
                // Right and up from the hinge, px.
                let (u, up) = (c as f64 + 0.5 - hx, g.hinge_row - (r as f64 + 0.5));
                w += wv;
                su += wv * u;
                sv += wv * up;
                suu += wv * u * u;
                svv += wv * up * up;
                suv += wv * u * up;
            }
        }
    }
    if w == 0.0 {
        return None;
    }
    let (mu, mv) = (su / w, sv / w);
    let (cuu, cvv, cuv) = (suu / w - mu * mu, svv / w - mv * mv, suv / w - mu * mv);
    // Along (sin θ, cos θ): c_uv = σ² sin θ cos θ, c_vv − c_uu = σ² cos 2θ.
    // (Only pixels above the cart are read: the axis's upward direction is the pole's,
    // within ±90°; a pole past horizontal has long fallen.)
    Some(PositionMsg {
        cart_pos_m: (hx - f64::from(img.width) / 2.0) / g.scale,
        pole_angle_rad: 0.5 * (2.0 * cuv).atan2(cvv - cuu),
    })
}

/// An image estimator node: it keeps nothing between frames (a frame is measured once, when
/// it is new).
pub struct ImageEstimator;

impl RustNode for ImageEstimator {
    type Input = ImageMsg;
    type Output = PositionMsg;

    fn tick(&mut self, _now: Nanos, frame: Option<&ImageMsg>) -> Option<PositionMsg> {
        measure(frame?)
    }

    fn save(&self) -> Option<NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        state.is::<()>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_the_camera_draws_the_estimator_measures_to_a_fraction_of_a_pixel() {
        for (w, h) in [(640, 480), (320, 240), (1024, 1024), (160, 120)] {
            let g = FrameGeometry::new(w, h);
            for (x, th) in [
                (0.0, 0.0),
                (0.5, 0.1),
                (-1.2, -0.2),
                (2.0, 0.05),
                (0.31, -0.013),
            ] {
                let m = measure(&g.frame(x, th))
                    .unwrap_or_else(|| panic!("{w}x{h} x={x} θ={th}: nothing measured ({g:?})"));
                // A pixel is 1/scale m; the angle's pixel at the tip 1/scale rad.
                let px = 1.0 / g.scale;
                assert!((m.cart_pos_m - x).abs() < 0.5 * px, "{w}x{h} x={x}: {m:?}");
                assert!(
                    (m.pole_angle_rad - th).abs() < 0.5 * px,
                    "{w}x{h} θ={th}: {m:?} (a pixel is {px} rad at the tip)"
                );
            }
        }
        // Not a frame it can read: nothing.
        let g = FrameGeometry::new(64, 48);
        let mut f = g.frame(0.0, 0.0);
        f.encoding = "rgb8".into();
        assert_eq!(measure(&f), None);
        let mut f = g.frame(0.0, 0.0);
        f.height += 1;
        assert_eq!(measure(&f), None);
        let blank = ImageMsg {
            data: vec![0; 64 * 48].into(),
            ..g.frame(0.0, 0.0)
        };
        assert_eq!(measure(&blank), None);
    }
}
