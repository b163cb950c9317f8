//! Welding equal points into shared, indexed vertices, in parallel and with the same result on
//! any number of threads: vertices are numbered in order of first use, as a serial pass over the
//! points would number them.
//!
//! The points are dealt by a hash of their bits into a fixed number of shards (a count, not a
//! share of the threads), each shard keeps its points in input order, and one hash map per shard
//! finds each point's first occurrence. Which occurrences are first does not depend on how the
//! shards were scheduled, and a prefix sum over those numbers them in input order.

use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicU32, Ordering};

/// Shards the points are dealt into (a power of two).
const SHARDS: usize = 64;
/// Points per chunk of the parallel passes: a size, so that the chunks are the same everywhere.
const CHUNK: usize = 1 << 16;

/// The welded points and, for each input point, the index of its vertex.
pub struct Welded {
    pub vertices: Vec<[f32; 3]>,
    pub indices: Vec<u32>,
}

/// A point's bits as a key, with -0 made +0 (`+ 0.0`) so that equal coordinates weld.
#[inline(always)]
fn key(v: Vec3) -> u128 {
    let [x, y, z] = (v + Vec3::ZERO).to_array().map(f32::to_bits);
    x as u128 | (y as u128) << 32 | (z as u128) << 64
}

#[inline(always)]
fn mix(k: u128) -> u64 {
    let h = (k as u64 ^ (k >> 64) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^ h >> 29
}

/// A hasher for keys that are already spread by [`mix`]: std's SipHash would cost more than the
/// rest of the weld.
#[derive(Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u128(&mut self, k: u128) {
        self.0 = mix(k);
    }
}

fn shard_of(k: u128) -> usize {
    (mix(k) >> (64 - SHARDS.trailing_zeros())) as usize
}

/// Welds `points` (each stored as `v + 0.0`), numbering vertices in order of first use.
pub fn weld(points: &[Vec3]) -> Welded {
    let n = points.len();
    assert!(n < u32::MAX as usize, "the compiler rejects scenes this large before welding");
    if n == 0 {
        return Welded { vertices: Vec::new(), indices: Vec::new() };
    }
    // Deal the points' indices into shards, each shard in input order: count per chunk and shard,
    // then every chunk writes its indices after those of the chunks before it.
    let keys: Vec<u128> = points.par_iter().map(|&v| key(v)).collect();
    let counts: Vec<[u32; SHARDS]> = keys
        .par_chunks(CHUNK)
        .map(|c| {
            let mut count = [0u32; SHARDS];
            for &k in c {
                count[shard_of(k)] += 1;
            }
            count
        })
        .collect();
    let mut starts = vec![[0usize; SHARDS]; counts.len()];
    let mut shard_start = [0usize; SHARDS + 1];
    let mut at = 0;
    for s in 0..SHARDS {
        shard_start[s] = at;
        for (c, count) in counts.iter().enumerate() {
            starts[c][s] = at;
            at += count[s] as usize;
        }
    }
    shard_start[SHARDS] = at;
    let dealt: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    keys.par_chunks(CHUNK).zip(&starts).enumerate().for_each(|(c, (chunk, start))| {
        let mut next = *start;
        for (i, &k) in chunk.iter().enumerate() {
            let s = shard_of(k);
            dealt[next[s]].store((c * CHUNK + i) as u32, Ordering::Relaxed);
            next[s] += 1;
        }
    });
    // Each point's first occurrence.
    let first: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    (0..SHARDS).into_par_iter().for_each(|s| {
        let range = shard_start[s]..shard_start[s + 1];
        let mut map: HashMap<u128, u32, BuildHasherDefault<KeyHasher>> =
            HashMap::with_capacity_and_hasher(range.len() / 2, Default::default());
        for d in &dealt[range] {
            let i = d.load(Ordering::Relaxed);
            let f = *map.entry(keys[i as usize]).or_insert(i);
            first[i as usize].store(f, Ordering::Relaxed);
        }
    });
    let is_first = |i: usize| first[i].load(Ordering::Relaxed) as usize == i;
    // Number the first occurrences in input order and store their vertices.
    let new_in_chunk: Vec<usize> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| (c * CHUNK..n.min(c * CHUNK + CHUNK)).filter(|&i| is_first(i)).count())
        .collect();
    let total: usize = new_in_chunk.iter().sum();
    let mut vertices = vec![[0f32; 3]; total];
    let mut parts = Vec::with_capacity(new_in_chunk.len());
    let mut rest = vertices.as_mut_slice();
    let mut base = 0;
    for &m in &new_in_chunk {
        let (part, r) = rest.split_at_mut(m);
        parts.push((part, base));
        rest = r;
        base += m;
    }
    let number: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    parts.into_par_iter().enumerate().for_each(|(c, (part, base))| {
        let firsts = (c * CHUNK..n.min(c * CHUNK + CHUNK)).filter(|&i| is_first(i));
        for ((i, out), id) in firsts.zip(part.iter_mut()).zip(base as u32..) {
            *out = (points[i] + Vec3::ZERO).to_array();
            number[i].store(id, Ordering::Relaxed);
        }
    });
    let indices = (0..n)
        .into_par_iter()
        .map(|i| number[first[i].load(Ordering::Relaxed) as usize].load(Ordering::Relaxed))
        .collect();
    Welded { vertices, indices }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The serial definition: a vertex per distinct point, numbered in order of first use.
    fn serial(points: &[Vec3]) -> Welded {
        let mut map = HashMap::new();
        let mut vertices = Vec::new();
        let indices = points
            .iter()
            .map(|&v| {
                *map.entry(key(v)).or_insert_with(|| {
                    vertices.push((v + Vec3::ZERO).to_array());
                    vertices.len() as u32 - 1
                })
            })
            .collect();
        Welded { vertices, indices }
    }

    #[test]
    fn parallel_welding_numbers_vertices_as_a_serial_pass_on_any_number_of_threads() {
        // Points on a coarse grid, so that most repeat, some as -0 against +0, spread over
        // several chunks.
        let mut seed = 7u32;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        let points: Vec<Vec3> = (0..3 * CHUNK + 123)
            .map(|_| {
                let c = |r: u32| match (r % 41) as f32 - 20.0 {
                    0.0 if r & 64 != 0 => -0.0,
                    x => x,
                };
                Vec3::new(c(rnd()), c(rnd()), c(rnd()))
            })
            .chain([Vec3::new(-0.0, 0.0, -0.0), Vec3::ZERO])
            .collect();
        let expected = serial(&points);
        assert!(expected.vertices.len() < points.len() / 2, "the points repeat");
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
            let got = pool.install(|| weld(&points));
            assert_eq!(got.vertices, expected.vertices, "{threads} threads");
            assert_eq!(got.indices, expected.indices, "{threads} threads");
        }
        let w = weld(&points);
        assert_eq!(w.indices[points.len() - 1], w.indices[points.len() - 2], "-0 welds with +0");
    }
}
