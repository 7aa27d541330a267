//! Soft bodies that may touch each other are stepped together: in each step the bodies whose
//! bounds (where they are, where they are headed, and a gap) overlap are joined into groups,
//! and the substeps of a group run in the core's `substeps_together` (in lockstep, two-way
//! soft contacts), its final pass at the step's finish. A body in no group runs
//! alone, as before. Groups run one after another, each group's bodies one per thread.

use parry3d::bounding_volume::{Aabb, BoundingVolume};

use super::*;
use crate::core::{LockstepBody, PairRounds, final_contacts_together, substeps_together};

/// This step's groups of soft bodies stepped together, found in the substeps' stage and kept
/// for the final pass. Scratch arrays are kept between steps.
#[derive(Resource, Default)]
pub(super) struct SoftContactGroups {
    /// The grouped bodies, group after group.
    members: Vec<Entity>,
    /// Where each group starts in `members`, and its end.
    starts: Vec<usize>,
    /// Candidates: each body taking part in soft contacts with its bounds and filter.
    candidates: Vec<(Entity, Aabb, CollisionFilter, bool)>,
    /// Union-find over the candidates.
    parent: Vec<usize>,
    /// The soft-contact passes' pairs, kept so that a step allocates none.
    rounds: PairRounds,
}

impl SoftContactGroups {
    /// The groups, and the pairs' scratch.
    fn groups(&mut self) -> (impl Iterator<Item = &[Entity]>, &mut PairRounds) {
        let members = &self.members;
        let groups = self.starts.windows(2).map(move |w| &members[w[0]..w[1]]);
        (groups, &mut self.rounds)
    }
}

fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Joins the bodies that may touch within a step of `h` into groups (a body meeting itself
/// makes a group of one), marks them `stepped_together`, and records the groups.
pub(super) fn find_groups(
    bodies: &mut Bodies,
    h: f32,
    gravity: Vec3,
    groups: &mut SoftContactGroups,
) {
    let groups = &mut *groups;
    groups.candidates.clear();
    groups.members.clear();
    groups.starts.clear();
    // What a particle can move beyond `x + h v` within the step: gravity's share.
    let fall = gravity.length() * h * h;
    for (entity, mut body, _) in bodies.iter_mut() {
        body.stepped_together = false;
        let state = &body.state;
        let Some(settings) = state.soft_contact_settings() else {
            continue;
        };
        if !body.placed {
            continue;
        }
        if let Some(bounds) = state.swept_bounds(h) {
            groups.candidates.push((
                entity,
                bounds.loosened(settings.thickness + fall),
                state.collision_filter(),
                state.is_sleeping() && !settings.self_contacts,
            ));
        }
    }
    let n = groups.candidates.len();
    groups.parent.clear();
    groups.parent.extend(0..n);
    let mut joined = vec![false; n];
    for a in 0..n {
        for b in a + 1..n {
            let (ca, cb) = (&groups.candidates[a], &groups.candidates[b]);
            if (ca.3 && cb.3) || !ca.2.interacts_with(cb.2) || !ca.1.intersects(&cb.1) {
                continue;
            }
            let (ra, rb) = (root(&mut groups.parent, a), root(&mut groups.parent, b));
            groups.parent[ra.max(rb)] = ra.min(rb);
            joined[a] = true;
            joined[b] = true;
        }
    }
    for (a, joined) in joined.iter_mut().enumerate() {
        let entity = groups.candidates[a].0;
        if !*joined && let Ok((_, body, _)) = bodies.get(entity) {
            *joined = body
                .state
                .soft_contact_settings()
                .is_some_and(|s| s.self_contacts);
        }
    }
    // Groups in the order of their first member (query order), members in query order.
    for a in 0..n {
        if !joined[a] || root(&mut groups.parent, a) != a {
            continue;
        }
        groups.starts.push(groups.members.len());
        for (b, &member) in joined.iter().enumerate().skip(a) {
            if member && root(&mut groups.parent, b) == a {
                groups.members.push(groups.candidates[b].0);
            }
        }
    }
    groups.starts.push(groups.members.len());
    for &entity in &groups.members {
        if let Ok((_, mut body, _)) = bodies.get_mut(entity) {
            body.stepped_together = true;
        }
    }
}

/// The substeps of every group: each body against its own copy of the spheres and rigid
/// bodies as they were before the stage, the group's changes to them merged as differences
/// after it (as `par_with_spheres` does for the bodies run alone).
pub(super) fn substeps_of_groups(
    bodies: &mut Bodies,
    groups: &mut SoftContactGroups,
    solver: &mut SolverSpheres,
    compute: &ComputePool,
    h: f32,
) {
    let before = solver.states.clone();
    let rigid_before = solver.rigid.clone();
    let (groups, rounds) = groups.groups();
    for group in groups {
        let mut members: Vec<(Mut<SoftBody>, Mut<SoftBodyStats>)> = Vec::with_capacity(group.len());
        for &entity in group {
            // SAFETY: the entities of a group are distinct, and this function borrows the
            // query mutably while the references live.
            if let Ok((_, body, stats)) = unsafe { bodies.get_unchecked(entity) } {
                members.push((body, stats));
            }
        }
        let start = Instant::now();
        let mut lockstep: Vec<LockstepBody> = members
            .iter_mut()
            .map(|(body, _)| {
                let body = &mut **body;
                body.spheres.clear();
                body.spheres.extend_from_slice(&before);
                let rigid = body.state.rigid_contacts_mut();
                for (mine, &id) in rigid.bodies.iter_mut().zip(&body.rigid_ids) {
                    *mine = rigid_before[id as usize];
                }
                LockstepBody::new(&mut body.state, &mut body.spheres)
            })
            .collect();
        substeps_together(&mut lockstep, h, &solver.colliders, compute, rounds);
        let counts: Vec<u32> = lockstep.iter().map(|b| b.contacts).collect();
        drop(lockstep);
        let share = start.elapsed() / group.len() as u32;
        for ((body, stats), contacts) in members.iter_mut().zip(counts) {
            stats.contacts += contacts;
            body.step_time += share;
            for ((sphere, mine), old) in solver.states.iter_mut().zip(&body.spheres).zip(&before) {
                sphere.velocity += mine.velocity - old.velocity;
            }
            let mine = &body.state.rigid_contacts().bodies;
            for (motion, &id) in mine.iter().zip(&body.rigid_ids) {
                let (all, old) = (&mut solver.rigid[id as usize], &rigid_before[id as usize]);
                all.linear_velocity += motion.linear_velocity - old.linear_velocity;
                all.angular_velocity += motion.angular_velocity - old.angular_velocity;
                all.position_correction += motion.position_correction - old.position_correction;
                all.rotation_correction += motion.rotation_correction - old.rotation_correction;
            }
        }
    }
}

/// The final soft-contact pass of every group, at the step's finish.
pub(super) fn final_pass_of_groups(
    bodies: &mut Bodies,
    groups: &mut SoftContactGroups,
    compute: &ComputePool,
) {
    let (groups, rounds) = groups.groups();
    for group in groups {
        let mut members: Vec<(Mut<SoftBody>, Mut<SoftBodyStats>)> = Vec::with_capacity(group.len());
        for &entity in group {
            // SAFETY: as in `substeps_of_groups`.
            if let Ok((_, body, stats)) = unsafe { bodies.get_unchecked(entity) } {
                members.push((body, stats));
            }
        }
        let mut lockstep: Vec<LockstepBody> = members
            .iter_mut()
            .map(|(body, _)| {
                let body = &mut **body;
                LockstepBody::new(&mut body.state, &mut body.spheres)
            })
            .collect();
        final_contacts_together(&mut lockstep, compute, rounds);
        let counts: Vec<u32> = lockstep.iter().map(|b| b.contacts).collect();
        drop(lockstep);
        for ((_, stats), contacts) in members.iter_mut().zip(counts) {
            stats.contacts += contacts;
        }
    }
}
