//! Seeded noise shared by both trial models: every random number of a trial
//! comes from a ChaCha8 stream seeded with the trial's seed (see
//! `protocol::seed`), drawn through these helpers so the NAO and the
//! synthetic model use one definition.

use rand::Rng;
use rand::SeedableRng;
pub use rand_chacha::ChaCha8Rng as Stream;

/// The trial's random stream.
#[must_use]
pub fn stream(seed: u64) -> Stream {
    Stream::seed_from_u64(seed)
}

/// A standard normal draw (Box–Muller; one value per call keeps the stream simple).
pub fn gauss(rng: &mut Stream) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * libm::log(u1)).sqrt() * libm::cos(std::f64::consts::TAU * u2)
}
