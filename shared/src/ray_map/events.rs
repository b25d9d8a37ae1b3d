//! What happened at a path vertex: a set of event bits, several at once (an emitter that reflects light is
//! both an emission and a reflection).

use crate::bsdf::{BsdfSample, LobeFlags};

/// The events at a vertex, as bits of one byte (the map stores them so).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Events(pub u8);

impl Events {
    /// A light path's origin on a light, or a camera path's hit on an emitter.
    pub const EMISSION: Events = Events(1);
    /// Diffuse (Lambertian) scattering.
    pub const DIFFUSE: Events = Events(1 << 1);
    /// Specular reflection: a mirror, a coating's reflected part, or Fresnel reflection at glass.
    pub const REFLECT: Events = Events(1 << 2);
    /// Transmission through glass (refraction) or straight through a coating.
    pub const REFRACT: Events = Events(1 << 3);
    /// Total internal reflection at glass (REFLECT is set as well).
    pub const TIR: Events = Events(1 << 4);
    /// The path ended here: absorbed by the surface or by Russian roulette.
    pub const ABSORB: Events = Events(1 << 5);
    /// A camera path's origin on the sensor (or the eye).
    pub const SENSOR: Events = Events(1 << 6);
    /// The path left the scene: the vertex's point is then the unit direction it left in.
    pub const ESCAPED: Events = Events(1 << 7);

    /// Every event with its name, as expressions and reports spell them.
    pub const NAMED: [(Events, &'static str); 8] = [
        (Events::EMISSION, "emission"),
        (Events::DIFFUSE, "diffuse"),
        (Events::REFLECT, "reflect"),
        (Events::REFRACT, "refract"),
        (Events::TIR, "tir"),
        (Events::ABSORB, "absorb"),
        (Events::SENSOR, "sensor"),
        (Events::ESCAPED, "escaped"),
    ];

    /// True when every bit of `other` is set here.
    #[inline]
    pub fn contains(self, other: Events) -> bool {
        self.0 & other.0 == other.0 && other.0 != 0
    }

    /// The names of the set bits joined by '+', or "-" for none.
    pub fn names(self) -> String {
        let names: Vec<&str> = Events::NAMED.iter().filter(|(e, _)| self.contains(*e)).map(|(_, n)| *n).collect();
        if names.is_empty() {
            "-".to_string()
        } else {
            names.join("+")
        }
    }
}

impl std::ops::BitOr for Events {
    type Output = Events;

    /// Both sets of events.
    fn bitor(self, o: Events) -> Events {
        Events(self.0 | o.0)
    }
}

impl std::ops::BitOrAssign for Events {
    /// Adds the events of `o`.
    fn bitor_assign(&mut self, o: Events) {
        self.0 |= o.0;
    }
}

/// The event of a sampled continuation: diffuse for a diffuse lobe, otherwise a reflection (with TIR where
/// glass could not have refracted) or a transmission. Glossy lobes record as the reflection or transmission
/// they are.
#[inline]
pub fn scatter_event(s: &BsdfSample) -> Events {
    if s.lobe.contains(LobeFlags::DIFFUSE) {
        Events::DIFFUSE
    } else if s.lobe.contains(LobeFlags::TRANSMISSION) {
        Events::REFRACT
    } else if s.lobe.contains(LobeFlags::TOTAL_INTERNAL) {
        Events::REFLECT | Events::TIR
    } else {
        Events::REFLECT
    }
}
