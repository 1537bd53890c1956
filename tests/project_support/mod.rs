//! Shared by the twin-project tests that need no training (`project_lock`, `survey_names`,
//! `hostile_projects`, `twin_commit`, `app_project_watch`): models small enough to write in
//! microseconds. Only what every one of them uses lives here (`one_gaussian` is `gaussians(1)`),
//! so no test crate carries an unused helper.

use damage_twin::splats::Splats;

/// A model of one grey Gaussian at the origin, without label channels.
pub fn one_gaussian() -> Splats {
    gaussians(1)
}

/// `count` grey Gaussians along x from the origin, one unit apart, without label channels.
pub fn gaussians(count: usize) -> Splats {
    let mut splats = Splats::empty(0, 0);
    for i in 0..count {
        splats.push(
            glam::Vec3::new(i as f32, 0.0, 0.0),
            glam::Vec3::ZERO,
            glam::Quat::IDENTITY,
            0.0,
            &[0.1, 0.2, 0.3],
            &[],
            0,
            0,
        );
    }
    splats
}
