//! Jobs over chunks of a body's particles, each with its own findings: the contact pass and
//! the integration run this way on the threads of a [`Parallel`], and their findings are
//! added up in chunk order afterwards, so the result does not depend on the thread count.

use super::parallel::{Parallel, SharedSlice};

/// Particles per job: enough jobs in the soft cube's 2 197 particles (nine) for two threads
/// to share them evenly.
pub(crate) const PARTICLE_CHUNK: usize = 256;

/// What one job found in its particles (contacts, particles that began touching, positions
/// that would not have been finite).
#[derive(Clone, Debug, Default)]
pub(crate) struct ChunkFindings {
    /// Particles that touch something for the first time this step, in index order (room for
    /// the whole chunk is kept, so steps do not allocate).
    pub(crate) new_touching: Vec<u32>,
    /// Contacts found.
    pub(crate) contacts: u32,
    /// Particles whose new position would not have been finite.
    pub(crate) non_finite: u32,
}

impl ChunkFindings {
    /// One per job for `particles` particles.
    pub(crate) fn for_particles(particles: usize) -> Vec<ChunkFindings> {
        (0..particles.div_ceil(PARTICLE_CHUNK))
            .map(|_| ChunkFindings {
                new_touching: Vec::with_capacity(PARTICLE_CHUNK.min(particles)),
                ..Default::default()
            })
            .collect()
    }
}

/// Runs `job` on every chunk of [`PARTICLE_CHUNK`] of `particles` particles, with that chunk's
/// findings (one per chunk, from [`ChunkFindings::for_particles`]), on the threads of
/// `parallel`.
pub(crate) fn in_particle_chunks(
    parallel: &dyn Parallel,
    findings: &mut [ChunkFindings],
    particles: usize,
    job: impl Fn(&mut ChunkFindings, std::ops::Range<usize>) + Sync,
) {
    // SAFETY: each job takes only its own chunk's findings.
    let findings = unsafe { SharedSlice::new(findings) };
    parallel.run(particles.div_ceil(PARTICLE_CHUNK), &|chunk| {
        // SAFETY: each job has its own chunk's findings.
        let found = unsafe { findings.get_mut(chunk) };
        job(
            found,
            PARTICLE_CHUNK * chunk..(PARTICLE_CHUNK * (chunk + 1)).min(particles),
        );
    });
}
