//! Named random streams and the replayable choice source.
//!
//! **Streams.** One master seed is split into named streams (`terrain`, `mission`, `peers`,
//! `sensor_noise`), so that changing how many draws one stage makes never changes what
//! another stage sees: the terrain of seed 7 is the same whatever the mission settings.
//! Each stream is a ChaCha8 generator keyed by the master seed (expanded with
//! `SeedableRng::seed_from_u64`, which is specified by `rand_core` and stable across
//! releases) and running on ChaCha's 64-bit stream number, set to the FNV-1a hash of the
//! stream's name. ChaCha streams with the same key and different stream numbers are
//! independent by construction.
//!
//! **Choices.** Every random choice of generation goes through a [`ChoiceSource`]. A choice is
//! a raw `u64` draw mapped to a value by a fixed, documented function, so a recorded list of
//! draws replays the same generation exactly, and a later shrinker can edit that list (a
//! draw of zero maps to the smallest value of every kind of choice, so zeroing draws
//! simplifies). When a replayed list runs out, further draws are zero.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};

/// The names of the streams that the pipeline stages draw from.
pub mod stream {
    /// Terrain sources (noise offsets, cave fill, rooms, rocks, mazes).
    pub const TERRAIN: &str = "terrain";
    /// Robot placement and routes.
    pub const MISSION: &str = "mission";
    /// Peer behaviour choices.
    pub const PEERS: &str = "peers";
    /// Sensor noise during a run.
    pub const SENSOR_NOISE: &str = "sensor_noise";
}

/// 64-bit FNV-1a hash of a stream name; fixed forever, as it decides every stream's draws.
pub fn stream_id(name: &str) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    name.bytes()
        .fold(OFFSET, |h, b| (h ^ u64::from(b)).wrapping_mul(PRIME))
}

/// Where a [`ChoiceSource`] takes its draws from.
#[derive(Debug, Clone)]
enum Origin {
    Random(Box<ChaCha8Rng>),
    Replay { draws: Vec<u64>, next: usize },
}

/// The one source of random choices for generation: draws from a seeded stream (optionally
/// recording them) or replays a recorded list.
#[derive(Debug, Clone)]
pub struct ChoiceSource {
    origin: Origin,
    record: Option<Vec<u64>>,
}

impl ChoiceSource {
    /// The stream `name` of master seed `seed`.
    pub fn stream(seed: u64, name: &str) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream_id(name));
        Self {
            origin: Origin::Random(Box::new(rng)),
            record: None,
        }
    }

    /// A source that replays `draws` in order, then gives zeros.
    pub fn replay(draws: Vec<u64>) -> Self {
        Self {
            origin: Origin::Replay { draws, next: 0 },
            record: None,
        }
    }

    /// Keep a copy of every draw from now on; read it back with [`ChoiceSource::recorded`].
    pub fn start_recording(&mut self) {
        self.record = Some(Vec::new());
    }

    /// The draws recorded since [`ChoiceSource::start_recording`], if recording.
    pub fn recorded(&self) -> Option<&[u64]> {
        self.record.as_deref()
    }

    /// One raw 64-bit draw: the primitive every other choice is made of.
    pub fn draw(&mut self) -> u64 {
        let value = match &mut self.origin {
            Origin::Random(rng) => rng.next_u64(),
            Origin::Replay { draws, next } => {
                let v = draws.get(*next).copied().unwrap_or(0);
                *next += 1;
                v
            }
        };
        if let Some(rec) = &mut self.record {
            rec.push(value);
        }
        value
    }

    /// A float in [0, 1) from the top 53 bits of one draw.
    pub fn unit(&mut self) -> f64 {
        (self.draw() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// A float in [lo, hi); `lo` when the draw is zero.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// An integer in [0, n) by Lemire's multiply-shift (one draw, bias below n / 2^64);
    /// 0 when `n` is 0.
    pub fn below(&mut self, n: u64) -> u64 {
        ((u128::from(self.draw()) * u128::from(n)) >> 64) as u64
    }

    /// An index into a collection of length `len` (which must be > 0).
    pub fn index(&mut self, len: usize) -> usize {
        self.below(len as u64) as usize
    }

    /// An integer in [lo, hi] (inclusive).
    pub fn int_in(&mut self, lo: i64, hi: i64) -> i64 {
        debug_assert!(lo <= hi);
        lo + self.below((hi - lo) as u64 + 1) as i64
    }

    /// A standard normal draw (mean 0, sd 1), by rand_distr's ziggurat: about one draw a
    /// sample and rarely a logarithm, where Box–Muller spends two draws, a logarithm, a root
    /// and a cosine (a sensor's noise is drawn for every beam of every scan).
    pub fn normal(&mut self) -> f64 {
        rand_distr::Distribution::sample(&rand_distr::StandardNormal, self)
    }

    /// True with probability `p`; false when the draw is zero and p < 1.
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() >= 1.0 - p
    }
}

/// Draws for rand_distr's samplers, through [`ChoiceSource::draw`] (so they are recorded and
/// replayed like any other choice).
impl rand_core::TryRng for ChoiceSource {
    type Error = core::convert::Infallible;

    fn try_next_u32(&mut self) -> Result<u32, Self::Error> {
        Ok((self.draw() >> 32) as u32)
    }

    fn try_next_u64(&mut self) -> Result<u64, Self::Error> {
        Ok(self.draw())
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Self::Error> {
        for chunk in dst.chunks_mut(8) {
            chunk.copy_from_slice(&self.draw().to_le_bytes()[..chunk.len()]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_draws_are_standard_normal_and_replay() {
        let mut live = ChoiceSource::stream(7, "normal");
        live.start_recording();
        let xs: Vec<f64> = (0..200_000).map(|_| live.normal()).collect();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        let within_1sd = xs.iter().filter(|x| x.abs() < 1.0).count() as f64 / n;
        let beyond_3sd = xs.iter().filter(|x| x.abs() > 3.0).count() as f64 / n;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.02, "{var}");
        assert!((within_1sd - 0.6827).abs() < 0.005, "{within_1sd}");
        assert!((beyond_3sd - 0.0027).abs() < 0.0008, "{beyond_3sd}");
        let mut replay = ChoiceSource::replay(live.recorded().unwrap().to_vec());
        assert!(xs.iter().all(|&x| replay.normal() == x));
    }

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u64> = (0..4)
            .map({
                let mut s = ChoiceSource::stream(7, stream::TERRAIN);
                move |_| s.draw()
            })
            .collect();
        let mut again = ChoiceSource::stream(7, stream::TERRAIN);
        let mut other = ChoiceSource::stream(7, stream::MISSION);
        let mut seed8 = ChoiceSource::stream(8, stream::TERRAIN);
        assert_eq!(a[0], again.draw());
        assert_ne!(a[0], other.draw());
        assert_ne!(a[0], seed8.draw());
    }

    #[test]
    fn recorded_draws_replay_the_same_choices() {
        let mut live = ChoiceSource::stream(42, stream::TERRAIN);
        live.start_recording();
        let values: Vec<f64> = (0..50).map(|i| live.uniform(-1.0, f64::from(i))).collect();
        let ints: Vec<i64> = (0..50).map(|i| live.int_in(-3, i)).collect();
        let mut replay = ChoiceSource::replay(live.recorded().unwrap().to_vec());
        let again: Vec<f64> = (0..50)
            .map(|i| replay.uniform(-1.0, f64::from(i)))
            .collect();
        let ints_again: Vec<i64> = (0..50).map(|i| replay.int_in(-3, i)).collect();
        assert_eq!(values, again);
        assert_eq!(ints, ints_again);
    }

    #[test]
    fn zero_draws_give_the_smallest_choice() {
        let mut z = ChoiceSource::replay(vec![]);
        assert_eq!(z.uniform(2.0, 5.0), 2.0);
        assert_eq!(z.int_in(-4, 9), -4);
        assert!(!z.chance(0.999));
        assert_eq!(z.below(10), 0);
    }

    #[test]
    fn below_stays_in_range() {
        let mut s = ChoiceSource::stream(1, "x");
        for n in 1..200u64 {
            assert!(s.below(n) < n);
        }
        assert_eq!(ChoiceSource::replay(vec![u64::MAX]).below(10), 9);
    }

    #[test]
    fn fnv1a_matches_published_vectors() {
        assert_eq!(stream_id(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(stream_id("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
