//! A scalar with its first two time derivatives: how the trajectory and the vibration hand
//! their C² motions to the inverse mechanization.

/// A scalar and its first two time derivatives (value, d/dt, d²/dt²).
pub type Jet = [f64; 3];
