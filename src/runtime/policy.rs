//! Brains: the function the policy node runs, observation → action, behind one trait.
//!
//! The chapter's point (ch2.8, `load_policy`) is that the brain is swappable: the sensor
//! and actuator only know two topics. [`Scripted`] is the built-in linear balancer;
//! checkpoint brains (PyTorch, safetensors, ONNX) live in [`crate::checkpoint`].
//! [`BrainSlot`] lets a running graph swap its brain between ticks.

use crate::plant::{Action, Observation};
use std::sync::{Arc, Mutex, MutexGuard};

/// A brain: maps one observation (`float32[5]`) to one action (`float32[1]`).
///
/// Implementations must be deterministic for a given input (the virtual clock's
/// byte-identical runs depend on it) and cheap enough for the policy's rate. An action may
/// be non-finite; the actuator then holds its last good action and counts the event.
pub trait Policy: Send {
    /// The action for `obs`. Not clipped: the plant clips to [-1, 1].
    fn act(&mut self, obs: &Observation) -> Action;
    /// A human-readable label naming the brain (and its file, if any).
    fn label(&self) -> String;
    /// A brain in the same state as this one, for a capture of the run
    /// ([`crate::runcore`]); `None` (the default) when it cannot be copied (a Python
    /// brain's objects), which makes a capture a replay. A brain whose action depends on
    /// the observation alone (the scripted balancer, a checkpoint's network) copies itself.
    fn duplicate(&self) -> Option<Box<dyn Policy>> {
        None
    }
}

/// The chapter's scripted balancer (the course's `balance_action` gains), computed from the
/// published observation only: θ = atan2(sin θ, cos θ);
/// u = 10θ + 2·pole_angvel + 0.4·cart_pos + 0.8·cart_vel, clipped to [-1, 1].
#[derive(Clone, Copy, Debug, Default)]
pub struct Scripted;

impl Policy for Scripted {
    fn act(&mut self, obs: &Observation) -> Action {
        let [x, x_dot, cos_t, sin_t, theta_dot] = obs.map(f64::from);
        let theta = sin_t.atan2(cos_t);
        let u = 10.0 * theta + 2.0 * theta_dot + 0.4 * x + 0.8 * x_dot;
        [u.clamp(-1.0, 1.0) as f32]
    }

    fn label(&self) -> String {
        "scripted balancer (built-in, checkpoint-free)".to_string()
    }

    fn duplicate(&self) -> Option<Box<dyn Policy>> {
        Some(Box::new(Scripted))
    }
}

/// A shared, swappable brain: the policy node locks it once per tick.
#[derive(Clone)]
pub struct BrainSlot(Arc<Mutex<Box<dyn Policy>>>);

impl BrainSlot {
    /// A slot holding `brain`.
    pub fn new(brain: Box<dyn Policy>) -> Self {
        Self(Arc::new(Mutex::new(brain)))
    }

    /// Lock the brain (a panicked brain's lock is still usable: the slot holds no invariant).
    pub fn lock(&self) -> MutexGuard<'_, Box<dyn Policy>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Replace the brain; the next policy tick uses the new one. Returns the old one.
    pub fn swap(&self, brain: Box<dyn Policy>) -> Box<dyn Policy> {
        std::mem::replace(&mut *self.lock(), brain)
    }

    /// The current brain's label.
    pub fn label(&self) -> String {
        self.lock().label()
    }

    /// A copy of the brain in the slot now ([`Policy::duplicate`]); `None` when it cannot
    /// be copied.
    pub fn save(&self) -> Option<Box<dyn Policy>> {
        self.lock().duplicate()
    }

    /// Put a copy of `saved` (what [`BrainSlot::save`] gave) in the slot. Returns false
    /// (the slot unchanged) when it cannot be copied again.
    pub fn load(&self, saved: &dyn Policy) -> bool {
        match saved.duplicate() {
            Some(brain) => {
                *self.lock() = brain;
                true
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scripted_gains_and_clip() {
        let mut p = Scripted;
        // θ = 0.01 rad (cos, sin), all else 0 → u = 0.1.
        let a = p.act(&[0.0, 0.0, 0.01f64.cos() as f32, 0.01f64.sin() as f32, 0.0]);
        assert!((a[0] - 0.1).abs() < 1e-6, "{a:?}");
        let a = p.act(&[1.0, 1.0, 1.0, 0.0, 0.5]); // 0.4 + 0.8 + 1.0 = 2.2 → 1
        assert_eq!(a, [1.0]);
        let a = p.act(&[-1.0, -1.0, 1.0, 0.0, -0.5]);
        assert_eq!(a, [-1.0]);
    }

    #[test]
    fn slot_swaps_brains() {
        struct Zero;
        impl Policy for Zero {
            fn act(&mut self, _: &Observation) -> Action {
                [0.0]
            }
            fn label(&self) -> String {
                "zero".into()
            }
        }
        let slot = BrainSlot::new(Box::new(Scripted));
        let old = slot.swap(Box::new(Zero));
        assert!(old.label().starts_with("scripted"));
        assert_eq!(slot.label(), "zero");
    }
}
