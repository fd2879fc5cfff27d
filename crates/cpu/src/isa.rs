//! `isa`: the instruction set the CPU backend's hot kernels run with, chosen once at run time.
//!
//! The default build targets the portable x86-64 baseline (SSE2), which every x86-64 CPU runs.
//! The triangle BVH's closest-hit traversal with its leaf tests, the triangle BVH build's
//! binning and partitioning and the deferred lighting bands are also compiled for AVX2 + FMA
//! (`x86-64-v3`) and AVX-512 (`x86-64-v4`), and [`dispatch`] runs each with the best set this
//! CPU has. Measured (BENCHMARKS.md, "Issue 20"), the other kernels stay on the baseline:
//! shadow rays' any-hit traversal (the switch cost its short rays more than the wider encoding
//! gained), the sphere BVH build (slower compiled for AVX2), the capsule and the raster (no
//! gain). `HYBRID_ISA=sse2|avx2|avx512` forces one (tests, comparisons); [`init_from_env`]
//! reads it, and a value this build or CPU does not offer is an error naming the variable.
//!
//! Runtime detection and the switch into code compiled for more features come from `pulp` (its
//! `V3`/`V4` tokens can only be made on a CPU that has the features, so the switch is safe
//! code). The kernels are the same Rust on every path: the wider paths only encode it with more
//! registers and three-operand (VEX/EVEX) instructions, and auto-vectorise loops wider. Rust
//! never fuses `a * b + c` into an FMA by itself and no kernel calls `mul_add`, so every path
//! gives the same bits, with one exception chosen for speed: on the AVX2 and AVX-512 paths the
//! triangle BVH's ray streams test boxes with fused multiply–subtracts (`fma_token`, `bvh`'s
//! `stream.rs`; 6–11% faster closest-hit streams), which can change the hit of a ray that
//! grazes a box boundary. Tested by rendering on every path this machine has
//! (`crates/cli/tests/isa.rs`: byte-identical outputs, but for at most one pixel in a thousand
//! of the images the trace stage's rays make; none differ in its renders) and by the BVH
//! tests in this crate.
//!
//! On aarch64 the baseline already has NEON, the only path there (`neon`); other targets run
//! their baseline (`portable`).

use std::sync::atomic::{AtomicU8, Ordering};

/// An instruction-set path of the hot kernels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// The target's baseline: SSE2 on x86-64, NEON on aarch64.
    Baseline,
    /// AVX2, FMA, BMI1/2, LZCNT, MOVBE (x86-64-v3).
    Avx2,
    /// x86-64-v3 plus AVX-512 F, BW, CD, DQ, VL (x86-64-v4).
    Avx512,
}

/// The name `HYBRID_ISA` takes for the baseline path.
#[cfg(target_arch = "x86_64")]
const BASELINE: &str = "sse2";
#[cfg(target_arch = "aarch64")]
const BASELINE: &str = "neon";
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
const BASELINE: &str = "portable";

/// Every path this build has, narrowest first.
const ALL: [Isa; 3] = [Isa::Baseline, Isa::Avx2, Isa::Avx512];

impl Isa {
    /// The name `HYBRID_ISA` and the frame report use.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => BASELINE,
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// Whether this build and this CPU can run the path.
    pub fn is_available(self) -> bool {
        match self {
            Isa::Baseline => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => pulp::x86::V3::is_available(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => pulp::x86::V4::is_available(),
            #[cfg(not(target_arch = "x86_64"))]
            Isa::Avx2 | Isa::Avx512 => false,
        }
    }

    /// The paths this machine can run, narrowest first (the baseline always).
    pub fn available() -> Vec<Isa> {
        ALL.into_iter().filter(|i| i.is_available()).collect()
    }

    /// The widest path this machine can run.
    pub fn best() -> Isa {
        ALL.into_iter().rev().find(|i| i.is_available()).unwrap_or(Isa::Baseline)
    }

    /// Parses a `HYBRID_ISA` value (case-insensitive) into a path this machine can run.
    pub fn parse(s: &str) -> Result<Isa, String> {
        let want = s.trim().to_ascii_lowercase();
        let names = || ALL.iter().map(|i| i.name()).collect::<Vec<_>>().join(", ");
        let isa = ALL
            .into_iter()
            .find(|i| i.name() == want)
            .ok_or_else(|| format!("`{s}` is not an instruction set path: use one of {}", names()))?;
        if !isa.is_available() {
            let have = Isa::available().iter().map(|i| i.name()).collect::<Vec<_>>().join(", ");
            return Err(format!("this CPU cannot run the `{}` path (it can run: {have})", isa.name()));
        }
        Ok(isa)
    }

    fn code(self) -> u8 {
        self as u8
    }
}

/// The path in use: `UNSET` until first asked, then an `Isa as u8`.
static ACTIVE: AtomicU8 = AtomicU8::new(UNSET);
const UNSET: u8 = u8::MAX;

/// The environment variable that forces a path.
pub const ENV: &str = "HYBRID_ISA";

/// Sets the path from `HYBRID_ISA` (the best one when unset or empty) and returns it; an
/// invalid or unavailable value is an error naming the variable, and leaves the path unchanged.
pub fn init_from_env() -> Result<Isa, String> {
    let isa = match std::env::var(ENV) {
        Ok(v) if !v.trim().is_empty() => Isa::parse(&v).map_err(|e| format!("{ENV}={v}: {e}"))?,
        Ok(_) | Err(std::env::VarError::NotPresent) => Isa::best(),
        Err(std::env::VarError::NotUnicode(v)) => return Err(format!("{ENV}={}: not valid UTF-8", v.to_string_lossy())),
    };
    set(isa);
    Ok(isa)
}

/// Switches the kernels to `isa` (which must be available: an unavailable one leaves the path
/// unchanged and returns false). Every path gives the same results, so switching while other
/// threads render changes only their speed.
pub fn set(isa: Isa) -> bool {
    if !isa.is_available() {
        return false;
    }
    ACTIVE.store(isa.code(), Ordering::Relaxed);
    true
}

/// The path in use. Unless [`set`] or [`init_from_env`] chose one, the first call takes
/// `HYBRID_ISA` when it names an available path and the best path otherwise.
#[inline]
pub fn active() -> Isa {
    match ACTIVE.load(Ordering::Relaxed) {
        0 => Isa::Baseline,
        1 => Isa::Avx2,
        2 => Isa::Avx512,
        _ => init_lazily(),
    }
}

#[cold]
fn init_lazily() -> Isa {
    init_from_env().unwrap_or_else(|_| {
        let best = Isa::best();
        set(best);
        best
    })
}

/// Runs `f` compiled for the active path. Only the code inlined into `f` gets the wider
/// encoding, so the kernels it calls are `#[inline(always)]` down to their loops; calls left out
/// of line still run, on the baseline encoding.
#[inline(always)]
pub fn dispatch<R>(f: impl FnOnce() -> R) -> R {
    match active() {
        Isa::Baseline => f(),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => match pulp::x86::V3::try_new() {
            Some(simd) => simd.vectorize(f),
            None => f(),
        },
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => match pulp::x86::V4::try_new() {
            Some(simd) => simd.vectorize(f),
            None => f(),
        },
        #[cfg(not(target_arch = "x86_64"))]
        Isa::Avx2 | Isa::Avx512 => f(),
    }
}

/// The AVX2 + FMA token when the path in use is AVX2 or AVX-512 (both have the FMA unit), for
/// kernels that choose fused multiply–adds on those paths (the ray streams' box tests); `None` on
/// the baseline.
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn fma_token() -> Option<pulp::x86::V3> {
    match active() {
        Isa::Baseline => None,
        Isa::Avx2 | Isa::Avx512 => pulp::x86::V3::try_new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_unknown_names_are_refused() {
        for isa in Isa::available() {
            assert_eq!(Isa::parse(isa.name()), Ok(isa));
            assert_eq!(Isa::parse(&isa.name().to_uppercase()), Ok(isa));
        }
        let e = Isa::parse("avx9").unwrap_err();
        assert!(e.contains("avx9") && e.contains(BASELINE), "{e}");
        assert!(Isa::available().contains(&Isa::Baseline));
        assert!(Isa::best().is_available());
    }

    #[test]
    fn unavailable_paths_are_refused_and_not_set() {
        for isa in ALL {
            if !isa.is_available() {
                assert!(Isa::parse(isa.name()).unwrap_err().contains("cannot run"));
                assert!(!set(isa));
            }
        }
    }

    #[test]
    fn dispatch_runs_the_closure_on_every_path() {
        let before = active();
        for isa in Isa::available() {
            assert!(set(isa));
            assert_eq!(active(), isa);
            let v: Vec<f32> = (0..37).map(|i| i as f32 * 0.37).collect();
            let s = dispatch(|| v.iter().map(|x| x * x + 1.0).sum::<f32>());
            let r = v.iter().map(|x| x * x + 1.0).sum::<f32>();
            assert_eq!(s.to_bits(), r.to_bits());
        }
        set(before);
    }
}
