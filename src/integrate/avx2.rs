//! Code compiled for AVX2 where the CPU has it: the integrator's hot loops
//! (the step loop of `integrate`, the Poincaré returns of `section`) run
//! through [`vectorised`] (or [`vectorised_or`]).

/// Runs `body` compiled for AVX2 where the CPU has it (runtime detection: a
/// binary built here must still run on an older CPU), as is otherwise. No
/// operation is fused or reordered, so the results are the same bits. The
/// body and what it calls must be inlined into it to be compiled so.
#[inline(always)]
pub(super) fn vectorised<R>(body: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2<R>(body: impl FnOnce() -> R) -> R {
            body()
        }
        // SAFETY: the CPU has the features the function is compiled for.
        return unsafe { avx2(body) };
    }
    body()
}

/// [`vectorised`] with a second body for an x86-64 CPU without AVX2, each
/// given `args` (the mutable state both would borrow):
/// `scalar`, which must compute the same bits (in the step loops: the same
/// trajectories stepped one at a time). Every x86-64 CPU since 2015 has
/// AVX2; compiling the batched loops a second time for the others, once per
/// model dimension, was a sixth of the crate's build time. Other
/// architectures run `fast` as is.
#[inline(always)]
pub(super) fn vectorised_or<A, R>(
    args: A,
    fast: impl FnOnce(A) -> R,
    scalar: impl FnOnce(A) -> R,
) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx2() {
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2<A, R>(args: A, body: impl FnOnce(A) -> R) -> R {
                body(args)
            }
            // SAFETY: the CPU has the features the function is compiled for.
            return unsafe { avx2(args, fast) };
        }
        let _ = fast;
        scalar(args)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = scalar;
        fast(args)
    }
}

/// Whether the CPU has AVX2 and FMA, and `LYAPSWEEP_NO_AVX2` is not set:
/// that variable runs what an older CPU runs, so that a test can check
/// that it computes the same bits.
#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *HAS.get_or_init(|| {
        std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
            && std::env::var_os("LYAPSWEEP_NO_AVX2").is_none_or(|v| v.is_empty())
    })
}
