//! The simulated world: a deterministic, time-ordered stream of sensor events.
