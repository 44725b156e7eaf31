//! Code compiled for AVX2 where the CPU has it: the integrator's hot loops
//! (the step loop of `integrate`, the Poincaré returns of `section`) run
//! through [`vectorised`].

/// Runs `body` compiled for AVX2 where the CPU has it (runtime detection: a
/// binary built here must still run on an older CPU), as is otherwise. No
/// operation is fused or reordered, so the results are the same bits. The
/// body and what it calls must be inlined into it to be compiled so.
#[inline(always)]
pub(super) fn vectorised<R>(body: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2<R>(body: impl FnOnce() -> R) -> R {
            body()
        }
        // SAFETY: the CPU has the features the function is compiled for.
        return unsafe { avx2(body) };
    }
    body()
}
