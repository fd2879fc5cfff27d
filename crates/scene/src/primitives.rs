//! Built-in primitives (paper §3): plane, cube, sphere with slices and stacks. STUB.
