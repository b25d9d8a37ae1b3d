//! A recorded path: its header (camera or light path, its pixel or emitter, phase, wavelength, weight) and its
//! vertices, quantised as the map stores them so that what a render records is exactly what a reader gets back.
//! Vertex 0 is the origin: a camera path's on the sensor (events SENSOR, no normal), a light path's on its
//! light (events EMISSION, the light's surface normal); neither is on an object, so the map stores only its
//! point and, for a light path, its normal.
//! The path walk fills one through its `PathLog` type parameter: `RecordedPath` records, `Unrecorded` compiles
//! to nothing, so a render that records no path pays nothing for the ability.

use super::events::Events;
use super::quantise::{decode_normal, encode_normal};
use crate::color::Rgb;
use crate::geometry::SurfaceHit;
use glam::Vec3;

/// `Vertex::object` of a vertex on no object (a camera path's sensor point, a point light, an escape).
pub const NO_OBJECT: u16 = u16::MAX;

/// Whether a path started at the camera or at a light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PathKind {
    Camera = 0,
    Light = 1,
}

/// One vertex: vertex 0 is the path's origin, every later one the end of a segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    /// World position; the unit direction of departure for an `ESCAPED` vertex.
    pub point: [f32; 3],
    /// The surface's geometric normal, octahedral (`quantise::decode_normal`); zero off surfaces.
    pub normal: u32,
    /// The scene object (index into the map's object names), or `NO_OBJECT`.
    pub object: u16,
    /// The triangle index, `u32::MAX` for analytic surfaces and off surfaces; the image pixel a light path's
    /// `SENSOR` vertex registered on.
    pub primitive: u32,
    pub events: Events,
}

impl Vertex {
    /// The position (or escape direction) as a vector.
    pub fn position(&self) -> Vec3 {
        Vec3::from_array(self.point)
    }

    /// The decoded normal.
    pub fn normal(&self) -> Vec3 {
        decode_normal(self.normal)
    }
}

/// A path as the map holds it.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedPath {
    pub kind: PathKind,
    /// The image pixel (y · width + x) of a camera path; the emitter (index into the map's emitter names) of a
    /// light path.
    pub source: u32,
    /// The 1-based phase the path was traced in.
    pub phase: u32,
    /// The path's number in its phase: its pixel, or its light-path index.
    pub item: u32,
    /// The wavelength the path was carried at once it met dispersion; 0 for an RGB path.
    pub wavelength_nm: f32,
    /// A camera path's contribution to its pixel in its phase (before gathered light); a light path's flux, or,
    /// when it registered on the sensor, the value it registered there in image terms (ΔΦ times the pixel's
    /// importance, before the division by the phase's light paths).
    pub weight: [f32; 3],
    pub vertices: Vec<Vertex>,
}

impl RecordedPath {
    /// An empty path of `kind`, number `item` of `phase`, from `source`.
    pub fn new(kind: PathKind, phase: u32, item: u32, source: u32) -> Self {
        RecordedPath { kind, source, phase, item, wavelength_nm: 0.0, weight: [0.0; 3], vertices: Vec::new() }
    }

    /// Starts the path again at `origin`, with the light's surface normal there for a light path.
    #[inline]
    pub fn begin(&mut self, origin: Vec3, normal: Vec3) {
        self.vertices.clear();
        let (normal, events) = match self.kind {
            PathKind::Camera => (Vec3::ZERO, Events::SENSOR),
            PathKind::Light => (normal, Events::EMISSION),
        };
        self.push(origin, normal, NO_OBJECT, u32::MAX, events);
    }

    /// Adds the vertex where the path met `hit`.
    #[inline]
    pub fn hit(&mut self, hit: &SurfaceHit) {
        // Scenes with more objects than a u16 holds are refused before recording starts.
        self.push(hit.p, hit.ng, hit.object as u16, hit.triangle, Events::default());
    }

    /// Adds events to the last vertex.
    #[inline]
    pub fn event(&mut self, events: Events) {
        if let Some(v) = self.vertices.last_mut() {
            v.events |= events;
        }
    }

    /// Adds the vertex where a light path crossed the sensor at `point` and registered on image pixel `pixel`,
    /// which the vertex keeps as its primitive.
    #[inline]
    pub fn sensor(&mut self, point: Vec3, pixel: u32) {
        self.push(point, Vec3::ZERO, NO_OBJECT, pixel, Events::SENSOR);
    }

    /// Adds the vertex of a path that left the scene in `direction`.
    #[inline]
    pub fn escape(&mut self, direction: Vec3) {
        self.push(direction, Vec3::ZERO, NO_OBJECT, u32::MAX, Events::ESCAPED);
    }

    /// Ends the path with its weight and wavelength.
    #[inline]
    pub fn finish(&mut self, weight: Rgb, wavelength_nm: Option<f32>) {
        self.weight = weight.to_array();
        self.wavelength_nm = wavelength_nm.unwrap_or(0.0);
    }

    /// The segments (vertices after the origin).
    pub fn segments(&self) -> usize {
        self.vertices.len().saturating_sub(1)
    }

    fn push(&mut self, p: Vec3, n: Vec3, object: u16, primitive: u32, events: Events) {
        self.vertices.push(Vertex { point: p.to_array(), normal: encode_normal(n), object, primitive, events });
    }
}

/// What the path walk tells a log as it goes: a `RecordedPath` keeps it, `Unrecorded` ignores it at no cost.
pub trait PathLog {
    /// True when the log keeps what it is told (false lets callers skip work done only for the log).
    const RECORDS: bool;

    /// Starts the path at `origin` (with the light's surface normal for a light path).
    fn begin(&mut self, origin: Vec3, normal: Vec3);
    /// Sets the path's source: a light path's emitter (`crate::ray_map::emitter_of`).
    fn set_source(&mut self, source: u32);
    /// The vertex where the path met `hit`.
    fn hit(&mut self, hit: &SurfaceHit);
    /// Events at the last vertex.
    fn event(&mut self, events: Events);
    /// A light path's crossing of the sensor at `point`, registered on image pixel `pixel`.
    fn sensor(&mut self, point: Vec3, pixel: u32);
    /// The path left the scene in `direction`.
    fn escape(&mut self, direction: Vec3);
    /// Ends the path with its weight and wavelength.
    fn finish(&mut self, weight: Rgb, wavelength_nm: Option<f32>);
}

impl PathLog for RecordedPath {
    const RECORDS: bool = true;

    #[inline]
    fn begin(&mut self, origin: Vec3, normal: Vec3) {
        RecordedPath::begin(self, origin, normal)
    }

    #[inline]
    fn set_source(&mut self, source: u32) {
        self.source = source;
    }

    #[inline]
    fn hit(&mut self, hit: &SurfaceHit) {
        RecordedPath::hit(self, hit)
    }

    #[inline]
    fn event(&mut self, events: Events) {
        RecordedPath::event(self, events)
    }

    #[inline]
    fn sensor(&mut self, point: Vec3, pixel: u32) {
        RecordedPath::sensor(self, point, pixel)
    }

    #[inline]
    fn escape(&mut self, direction: Vec3) {
        RecordedPath::escape(self, direction)
    }

    #[inline]
    fn finish(&mut self, weight: Rgb, wavelength_nm: Option<f32>) {
        RecordedPath::finish(self, weight, wavelength_nm)
    }
}

/// The log of a path nobody records: every call is empty and compiles away.
#[derive(Clone, Copy, Debug, Default)]
pub struct Unrecorded;

impl PathLog for Unrecorded {
    const RECORDS: bool = false;

    #[inline(always)]
    fn begin(&mut self, _: Vec3, _: Vec3) {}

    #[inline(always)]
    fn set_source(&mut self, _: u32) {}

    #[inline(always)]
    fn hit(&mut self, _: &SurfaceHit) {}

    #[inline(always)]
    fn event(&mut self, _: Events) {}

    #[inline(always)]
    fn sensor(&mut self, _: Vec3, _: u32) {}

    #[inline(always)]
    fn escape(&mut self, _: Vec3) {}

    #[inline(always)]
    fn finish(&mut self, _: Rgb, _: Option<f32>) {}
}
