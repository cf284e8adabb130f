//! The camera as the film sees it: rays through film positions (a pinhole
//! or a thin lens, moving over the shutter), the pixel filter that places
//! each sample on the film, and screen-space motion for motion vectors.

use std::f32::consts::PI;

use glam::{Affine3A, Vec2, Vec3};

use super::accel::{Hit, WorldRay};
use super::sampler::Sampler;
use super::sampling::sample_concentric_disk;
use super::surface::object_point;
use super::RenderSettings;
use crate::scene::{FrameScene, Library};

/// Pixel filter: a radially truncated Gaussian, importance-sampled exactly.
pub(crate) const FILTER_RADIUS: f32 = 1.5;
const FILTER_SIGMA: f32 = 0.5;

/// One camera sample up to its camera ray: its sampler (past the film
/// offset, time and lens draws), the film offset and the ray.
#[derive(Clone, Debug)]
pub(crate) struct CameraSample {
    pub(crate) sampler: Sampler,
    pub(crate) offset: Vec2,
    pub(crate) ray: WorldRay,
}

/// The camera's rays: looks down its local -Z, +Y up, vertical field of
/// view; a thin lens of radius `aperture` focused at `focus_distance`, or a
/// pinhole.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    world_from_camera: Affine3A,
    camera_from_world: Affine3A,
    tan_half_y: f32,
    aspect: f32,
    width: f32,
    height: f32,
    aperture: f32,
    focus_distance: f32,
}

impl CameraRays {
    /// Camera for an image of `width` x `height` pixels.
    pub fn new(camera: &crate::scene::Camera, width: u32, height: u32) -> CameraRays {
        CameraRays {
            world_from_camera: camera.world_from_camera,
            camera_from_world: camera.world_from_camera.inverse(),
            tan_half_y: (0.5 * camera.yfov).tan(),
            aspect: width as f32 / height.max(1) as f32,
            width: width as f32,
            height: height as f32,
            aperture: camera.aperture.max(0.0),
            focus_distance: camera.focus_distance,
        }
    }

    /// Whether rays start across a lens (depth of field) rather than at a point.
    pub(crate) fn has_lens(&self) -> bool {
        self.aperture > 0.0 && self.focus_distance > 0.0
    }

    /// The world ray (origin, unit direction) through film position
    /// (fx, fy) in pixels, y down, (0, 0) the top-left corner.
    pub fn ray(&self, fx: f32, fy: f32) -> (Vec3, Vec3) {
        let sx = (2.0 * fx / self.width - 1.0) * self.aspect * self.tan_half_y;
        let sy = (1.0 - 2.0 * fy / self.height) * self.tan_half_y;
        let d = self.world_from_camera.transform_vector3(Vec3::new(sx, sy, -1.0)).normalize();
        (self.world_from_camera.translation.into(), d)
    }

    /// As [`CameraRays::ray`], from lens point `u` (uniform in [0, 1)^2):
    /// every ray through one film position meets at the focus plane, so a
    /// point there images to a point and others blur by their circle of
    /// confusion. A pinhole camera ignores `u`.
    pub(crate) fn lens_ray(&self, fx: f32, fy: f32, u: Vec2) -> (Vec3, Vec3) {
        if !self.has_lens() {
            return self.ray(fx, fy);
        }
        let sx = (2.0 * fx / self.width - 1.0) * self.aspect * self.tan_half_y;
        let sy = (1.0 - 2.0 * fy / self.height) * self.tan_half_y;
        let focus = Vec3::new(sx, sy, -1.0) * self.focus_distance;
        let lens = sample_concentric_disk(u) * self.aperture;
        let origin = Vec3::new(lens.x, lens.y, 0.0);
        let o = self.world_from_camera.transform_point3(origin);
        let d = self.world_from_camera.transform_vector3(focus - origin).normalize();
        (o, d)
    }

    /// Camera-space depth of a world point, positive in front of the camera.
    pub(crate) fn depth(&self, p: Vec3) -> f32 {
        -self.camera_from_world.transform_point3(p).z
    }

    /// The film position (pixels, y down, (0, 0) the top-left corner) a
    /// world point projects to; `None` behind the camera. Inverse of [`CameraRays::ray`].
    pub(crate) fn raster(&self, p: Vec3) -> Option<Vec2> {
        let c = self.camera_from_world.transform_point3(p);
        if !(c.z < 0.0) {
            return None;
        }
        let (sx, sy) = (c.x / -c.z, c.y / -c.z);
        Some(Vec2::new(
            (sx / (self.aspect * self.tan_half_y) + 1.0) * 0.5 * self.width,
            (1.0 - sy / self.tan_half_y) * 0.5 * self.height,
        ))
    }
}

/// The camera over the shutter: rays at a time, and the film positions at
/// open and close for motion vectors.
#[derive(Clone, Copy, Debug)]
struct ShutterCamera {
    keys: [CameraRays; 2],
    /// Whether the two keys differ (else rays come from the frame camera).
    moves: bool,
    /// Shutter length in frames (> 0).
    length: f32,
}

/// The frame's camera: its rays at shutter open and, with motion, its two
/// shutter keys.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FilmCamera {
    rays: CameraRays,
    shutter: Option<ShutterCamera>,
}

impl FilmCamera {
    /// The camera of `scene` for an image of `settings`' size.
    pub(crate) fn new(scene: &FrameScene, settings: &RenderSettings) -> FilmCamera {
        let shutter = scene.motion.as_ref().map(|m| {
            let [a, b] = m.camera;
            ShutterCamera {
                keys: [a, b].map(|c| CameraRays::new(&c, settings.width, settings.height)),
                moves: a.world_from_camera != b.world_from_camera
                    || a.yfov != b.yfov
                    || a.world_from_camera != scene.camera.world_from_camera
                    || a.yfov != scene.camera.yfov,
                length: (m.shutter[1] - m.shutter[0]).max(1e-6),
            }
        });
        FilmCamera { rays: CameraRays::new(&scene.camera, settings.width, settings.height), shutter }
    }

    /// Whether the scene moves over a shutter (rays then carry a time).
    pub(crate) fn has_shutter(&self) -> bool {
        self.shutter.is_some()
    }

    /// Camera-space depth of a world point at shutter open, positive in front of the camera.
    pub(crate) fn depth(&self, p: Vec3) -> f32 {
        self.rays.depth(p)
    }

    /// Camera sample `sample` of pixel (x, y) up to its camera ray: the
    /// sampler, the film offset and the ray, drawn as `Integrator::sample_pixel` draws them.
    pub(crate) fn sample(&self, s: &RenderSettings, x: u32, y: u32, sample: u32) -> CameraSample {
        let mut sampler = Sampler::new(s.seed, s.frame, s.layer, x, y, sample);
        let offset = sample_filter(sampler.next_2d());
        let (fx, fy) = (x as f32 + 0.5 + offset.x, y as f32 + 0.5 + offset.y);
        // The time stream is drawn only with a shutter, and draws no dimension.
        let time = if self.shutter.is_some() { sampler.time() } else { 0.0 };
        // The lens stream likewise, only with depth of field.
        let lens = if self.rays.has_lens() { sampler.lens() } else { Vec2::ZERO };
        let (origin, dir) = match &self.shutter {
            Some(sh) if sh.moves => {
                let ((o0, d0), (o1, d1)) = (sh.keys[0].lens_ray(fx, fy, lens), sh.keys[1].lens_ray(fx, fy, lens));
                (o0.lerp(o1, time), d0.lerp(d1, time).normalize())
            }
            _ => self.rays.lens_ray(fx, fy, lens),
        };
        CameraSample { sampler, offset, ray: WorldRay { origin, direction: dir, tmax: f32::INFINITY, time } }
    }

    /// Screen-space motion (pixels per frame, +v up) of the surface point
    /// `hit` found on one of `scene`'s instances: where the point is at
    /// shutter open and close, through the camera at each.
    pub(crate) fn motion_vector(&self, lib: &Library, scene: &FrameScene, hit: &Hit) -> Vec2 {
        let (i, triangle, u, v) = (hit.instance as usize, hit.triangle, hit.u, hit.v);
        let Some(sh) = &self.shutter else { return Vec2::ZERO };
        let (Some(inst), Some(m)) = (scene.instances.get(i), scene.motion.as_ref().and_then(|m| m.instances.get(i)))
        else {
            return Vec2::ZERO;
        };
        let Some(mesh) = lib.meshes.get(inst.mesh as usize) else { return Vec2::ZERO };
        let tri = triangle as usize * 3;
        let Some(idx) = mesh.indices.get(tri..tri + 3) else { return Vec2::ZERO };
        let idx = [idx[0] as usize, idx[1] as usize, idx[2] as usize];
        let hi = m
            .deform
            .and_then(|d| lib.meshes.get(d.mesh as usize))
            .filter(|h| h.positions.len() == mesh.positions.len());
        let weights = m.deform.map_or([0.0; 2], |d| d.weight);
        let key = |k: usize, world_from_object: &Affine3A| {
            let p = object_point(mesh, hi.map(|h| (h, weights[k])), idx, u, v)?;
            sh.keys[k].raster(world_from_object.transform_point3(p))
        };
        match (key(0, &inst.world_from_object), key(1, &m.world_from_object_close)) {
            (Some(a), Some(b)) => {
                let d = (b - a) / sh.length;
                if d.is_finite() {
                    Vec2::new(d.x, -d.y)
                } else {
                    Vec2::ZERO
                }
            }
            _ => Vec2::ZERO,
        }
    }
}

/// Maps a uniform 2D point to a film offset (pixels) distributed as the
/// truncated Gaussian filter, so every sample has weight 1 (filter
/// importance sampling): inverse CDF of the radial distribution.
pub(crate) fn sample_filter(u: Vec2) -> Vec2 {
    let tail = 1.0 - (-FILTER_RADIUS * FILTER_RADIUS / (2.0 * FILTER_SIGMA * FILTER_SIGMA)).exp();
    let r = FILTER_SIGMA * (-2.0 * (1.0 - u.x * tail).ln()).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec2::new(r * phi.cos(), r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filter_stays_in_radius() {
        for i in 0..64 {
            for j in 0..64 {
                let o = sample_filter(Vec2::new(i as f32 / 64.0, j as f32 / 64.0));
                assert!(o.length() <= FILTER_RADIUS + 1e-4);
            }
        }
    }
}
