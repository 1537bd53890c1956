//! Shared by the twin-project tests that need no training (`project_lock`, `survey_names`,
//! `hostile_projects`): a model small enough to write in microseconds. Only what every one of
//! them uses lives here, so no test crate carries an unused helper.

use damage_twin::splats::Splats;

/// A model of one grey Gaussian at the origin, without label channels.
pub fn one_gaussian() -> Splats {
    let mut splats = Splats::empty(0, 0);
    splats.push(
        glam::Vec3::ZERO,
        glam::Vec3::ZERO,
        glam::Quat::IDENTITY,
        0.0,
        &[0.1, 0.2, 0.3],
        &[],
        0,
        0,
    );
    splats
}
