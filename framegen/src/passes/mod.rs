//! Every pass, one module each with its WGSL beside it and a plain CPU
//! reference: what the methods share ([`common`]), GFFE's ([`gffe`]) and
//! GeoMotionGen's ([`interp`]).

pub mod common;
pub mod gffe;
pub mod interp;
