//! The Scout simulator.
//!
//! # Layout
//! This crate will hold worlds of polygon obstacles, differential-drive Scout
//! robots with a ring of 16 sonars, and the gRPC `RobotService`. The sonar
//! ring's geometry it will use is [`deog_grid::SensorRing`]. It holds no code yet.
