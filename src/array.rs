//! Small fixed-size arrays built element by element.

use std::mem::MaybeUninit;

/// `[f(0), f(1), …, f(N - 1)]`, as [`std::array::from_fn`] builds it, for
/// elements that are plain data (`Copy`).
///
/// Why not the standard one: it goes through a fallible builder with a drop
/// guard, instantiated anew for every closure. The lane code builds its
/// per-lane and per-state arrays with well over a hundred closures, each
/// monomorphised for every system dimension and batch width, and those
/// builders were an eighth of the crate's LLVM input and a matching share of
/// its release build time. With `Copy` elements nothing needs dropping if
/// `f` panics, so a plain loop over uninitialised slots is enough.
pub fn from_fn<T: Copy, const N: usize>(mut f: impl FnMut(usize) -> T) -> [T; N] {
    let mut out = [MaybeUninit::<T>::uninit(); N];
    for (i, slot) in out.iter_mut().enumerate() {
        slot.write(f(i));
    }
    // SAFETY: the loop above wrote every slot, and `MaybeUninit<T>` has the
    // layout of `T`, so `[MaybeUninit<T>; N]` has that of `[T; N]`.
    unsafe { out.as_ptr().cast::<[T; N]>().read() }
}

#[cfg(test)]
mod tests {
    #[test]
    fn builds_what_the_standard_one_builds() {
        let ours: [[f64; 3]; 4] = super::from_fn(|i| super::from_fn(|k| (i * 10 + k) as f64));
        let std: [[f64; 3]; 4] =
            std::array::from_fn(|i| std::array::from_fn(|k| (i * 10 + k) as f64));
        assert_eq!(ours, std);
        let empty: [u8; 0] = super::from_fn(|_| unreachable!());
        assert_eq!(empty, []);
    }
}
