//! A coloured sparse point cloud (SfM points, `points.ply`): the usual splat initialisation.

use glam::Vec3;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    pub positions: Vec<Vec3>,
    /// sRGB colours, 0..=255.
    pub colours: Vec<[u8; 3]>,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}
