//! The validator's scans on every thread. Each thread scans pieces of a fixed size in a plain
//! loop: rayon's per-item iterators check a shared flag at every item, which made a scan several
//! times slower than the serial loop it replaced.

use rayon::prelude::*;

/// Items per piece.
const PIECE: usize = 1 << 14;

/// Whether `f(index, item)` holds for every item.
pub(crate) fn all<T: Sync>(items: &[T], f: impl Fn(usize, &T) -> bool + Sync) -> bool {
    items.par_chunks(PIECE).enumerate().all(|(c, piece)| piece.iter().enumerate().all(|(j, x)| f(c * PIECE + j, x)))
}

/// The index of the first item for which `f` holds, as a serial scan would find it.
pub(crate) fn position_first<T: Sync>(items: &[T], f: impl Fn(&T) -> bool + Sync) -> Option<usize> {
    let c = items.par_chunks(PIECE).position_first(|piece| piece.iter().any(&f))?;
    items[c * PIECE..].iter().position(&f).map(|j| c * PIECE + j)
}
