//! The executors that run the passes: the CPU reference on all cores
//! ([`cpu`]) and wgpu compute over persistent buffers ([`gpu`]). Both
//! implement [`crate::pipeline::Backend`]; the GPU device, kernels and
//! timing they use are the infrastructure in [`crate::gpu`].

pub mod cpu;
pub mod gpu;
