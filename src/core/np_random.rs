//! numpy-compatible random draws, so `reset(seed)` starts exactly where the course's env does.
//!
//! The course seeds with `numpy.random.Generator(PCG64(seed))`. That is numpy's
//! `SeedSequence` (entropy pool of four 32-bit words, hash-mixed; Melissa O'Neill's
//! seed_seq design as numpy implements it in `bit_generator.pyx`) feeding the
//! PCG XSL RR 128/64 generator (the 128-bit LCG is [`rand_pcg::Lcg128Xsl64`]), and doubles
//! are `(next_u64 >> 11) * 2^-53`. Only the seeding is written here; the generator is
//! the well-kept `rand_pcg` crate.

use rand_core::Rng;
use rand_pcg::Lcg128Xsl64;

const INIT_A: u32 = 0x43b0_d7e5;
const MULT_A: u32 = 0x931e_8875;
const INIT_B: u32 = 0x8b51_f9dd;
const MULT_B: u32 = 0x58f3_8ded;
const MIX_MULT_L: u32 = 0xca01_f9dd;
const MIX_MULT_R: u32 = 0x4973_f715;
const XSHIFT: u32 = 16;
const POOL_SIZE: usize = 4;

fn hashmix(value: u32, hash_const: &mut u32) -> u32 {
    let mut v = value ^ *hash_const;
    *hash_const = hash_const.wrapping_mul(MULT_A);
    v = v.wrapping_mul(*hash_const);
    v ^ (v >> XSHIFT)
}

fn mix(x: u32, y: u32) -> u32 {
    let r = MIX_MULT_L
        .wrapping_mul(x)
        .wrapping_sub(MIX_MULT_R.wrapping_mul(y));
    r ^ (r >> XSHIFT)
}

/// numpy's `SeedSequence(seed).generate_state(n_words, np.uint32)` for an integer seed.
pub fn seed_sequence_state(seed: u64, n_words: usize) -> Vec<u32> {
    // numpy splits an integer seed into little-endian 32-bit words (at least one word).
    let mut entropy = vec![seed as u32];
    if seed >> 32 != 0 {
        entropy.push((seed >> 32) as u32);
    }
    let mut pool = [0u32; POOL_SIZE];
    let mut hash_const = INIT_A;
    for (i, slot) in pool.iter_mut().enumerate() {
        *slot = hashmix(entropy.get(i).copied().unwrap_or(0), &mut hash_const);
    }
    for i_src in 0..POOL_SIZE {
        for i_dst in 0..POOL_SIZE {
            if i_src != i_dst {
                pool[i_dst] = mix(pool[i_dst], hashmix(pool[i_src], &mut hash_const));
            }
        }
    }
    for &word in entropy.iter().skip(POOL_SIZE) {
        for slot in pool.iter_mut() {
            *slot = mix(*slot, hashmix(word, &mut hash_const));
        }
    }
    let mut hash_const = INIT_B;
    (0..n_words)
        .map(|i| {
            let mut v = pool[i % POOL_SIZE] ^ hash_const;
            hash_const = hash_const.wrapping_mul(MULT_B);
            v = v.wrapping_mul(hash_const);
            v ^ (v >> XSHIFT)
        })
        .collect()
}

/// `numpy.random.Generator(PCG64(seed))`: same seed, same stream of doubles.
pub struct NumpyGenerator {
    pcg: Lcg128Xsl64,
}

impl NumpyGenerator {
    /// Seeded as `PCG64(seed)` is: four `uint64` words from the seed sequence give the
    /// 128-bit initial state (words 0, 1: high, low) and stream (words 2, 3).
    pub fn new(seed: u64) -> Self {
        let w = seed_sequence_state(seed, 8);
        let u64_at = |i: usize| u64::from(w[2 * i]) | (u64::from(w[2 * i + 1]) << 32);
        let state = (u128::from(u64_at(0)) << 64) | u128::from(u64_at(1));
        let stream = (u128::from(u64_at(2)) << 64) | u128::from(u64_at(3));
        Self {
            pcg: Lcg128Xsl64::new(state, stream),
        }
    }

    /// `Generator.random()`: a double in [0, 1) with 53 random bits.
    pub fn random(&mut self) -> f64 {
        (self.pcg.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }

    /// `Generator.uniform(low, high)`: `low + (high - low) * random()`.
    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.random()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_zero_matches_numpy() {
        // numpy: Generator(PCG64(0)).uniform(-0.05, 0.05, size=2), twice. The second draw
        // (θ) is checked after the env's wrap to [-π, π) in the plant's reset test.
        let mut g = NumpyGenerator::new(0);
        let draws: Vec<f64> = (0..4).map(|_| g.uniform(-0.05, 0.05)).collect();
        assert_eq!(draws[0], 0.013696168732145436);
        assert_eq!(draws[2], -0.045902647606380534);
        assert_eq!(draws[3], -0.04834723644714709);
        assert!((draws[1] - -0.02302132862361317).abs() < 1e-15);
    }
}
