//! The TOML scene format as it is written on disk (see `scenes/README.md` for the reference).

use serde::Deserialize;
use std::collections::BTreeMap;
use toml::Spanned;

/// A whole scene file.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub render: RenderSection,
    pub camera: Spanned<CameraSection>,
    #[serde(default)]
    pub materials: BTreeMap<String, Spanned<MaterialSection>>,
    #[serde(default)]
    pub objects: Vec<Spanned<ObjectSection>>,
    #[serde(default)]
    pub lights: Vec<Spanned<LightSection>>,
}

/// Integrator settings stored with the scene, so that a scene renders the same everywhere.
#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct RenderSection {
    pub max_depth: Option<Spanned<u32>>,
    pub backward_diffuse_depth: Option<Spanned<u32>>,
    pub radius_scale: Option<Spanned<f32>>,
    pub light_paths_per_pixel: Option<Spanned<f32>>,
    pub ghost_light_paths: Option<bool>,
    pub ghost_paths: Option<Spanned<u32>>,
    pub ghost_radius: Option<Spanned<f32>>,
}

/// The camera.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    #[serde(rename = "type", default = "pinhole")]
    pub kind: Spanned<String>,
    pub position: Spanned<[f32; 3]>,
    pub look_at: Spanned<[f32; 3]>,
    #[serde(default = "up_y")]
    pub up: Spanned<[f32; 3]>,
    /// Pinhole and thin-lens cameras only.
    pub fov_y_deg: Option<Spanned<f32>>,
    pub width: Spanned<u32>,
    pub height: Spanned<u32>,
    pub lens_radius: Option<Spanned<f32>>,
    pub focus_distance: Option<Spanned<f32>>,
    /// Sensor camera: the sensor's width in metres.
    pub sensor_width: Option<Spanned<f32>>,
    /// Sensor camera: the name of the `lens_surface` object nearest the sensor (the rear element).
    pub rear_element: Option<Spanned<String>>,
}

fn pinhole() -> Spanned<String> {
    Spanned::new(0..0, "pinhole".to_string())
}

fn up_y() -> Spanned<[f32; 3]> {
    Spanned::new(0..0, [0.0, 1.0, 0.0])
}

/// A material definition; `type` selects the family. Every family also takes `opacity` (a number or a texture:
/// the probability that the surface is there, for cut-outs) and `back` ("same", the default, "black" for a
/// one-sided surface, or the name of another material whose family scatters on the back).
#[derive(Deserialize, Debug)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum MaterialSection {
    Diffuse {
        /// A colour, a grey or a texture table (scenes/README.md, "Textures"); a constant one multiplies
        /// `albedo_texture` when both are given; required without `albedo_texture`.
        albedo: Option<toml::Value>,
        /// An image file (sRGB where its samples are integers) relative to the scene file: the older spelling of
        /// `albedo = { bitmap = "..." }`.
        albedo_texture: Option<String>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    Mirror {
        #[serde(default = "ones")]
        reflectance: [f32; 3],
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    /// A metal, smooth or (with a roughness) rough.
    Conductor {
        /// A named metal (Mitsuba 3's names, e.g. "Au"), or "none" for a perfect mirror; else `eta` and `k`.
        material: Option<String>,
        eta: Option<toml::Value>,
        k: Option<toml::Value>,
        specular_reflectance: Option<toml::Value>,
        /// The microfacet roughness (a number or a texture); none: a smooth surface.
        alpha: Option<toml::Value>,
        /// Anisotropic roughness along the shading frame's two tangents, instead of `alpha`.
        alpha_u: Option<toml::Value>,
        alpha_v: Option<toml::Value>,
        /// "beckmann" (the default) or "ggx".
        distribution: Option<String>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    Dielectric {
        ior: f32,
        #[serde(default = "one")]
        ext_ior: f32,
        #[serde(default)]
        anti_reflection: bool,
        /// Abbe number V_d of the glass behind the surface: makes `ior` vary with wavelength (Cauchy).
        abbe: Option<f32>,
        /// Abbe number of the medium in front (a cemented surface between two glasses).
        ext_abbe: Option<f32>,
        specular_reflectance: Option<toml::Value>,
        specular_transmittance: Option<toml::Value>,
        /// The microfacet roughness (a number or a texture); none: a smooth surface.
        alpha: Option<toml::Value>,
        /// Anisotropic roughness along the shading frame's two tangents, instead of `alpha`.
        alpha_u: Option<toml::Value>,
        alpha_v: Option<toml::Value>,
        /// "beckmann" (the default) or "ggx".
        distribution: Option<String>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    ThinDielectric {
        ior: f32,
        #[serde(default = "one")]
        ext_ior: f32,
        specular_reflectance: Option<toml::Value>,
        specular_transmittance: Option<toml::Value>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    /// A diffuse base under a dielectric coat, smooth or (with a roughness) rough.
    Plastic {
        diffuse_reflectance: Option<toml::Value>,
        specular_reflectance: Option<toml::Value>,
        ior: Option<f32>,
        ext_ior: Option<f32>,
        #[serde(default)]
        nonlinear: bool,
        /// The microfacet roughness (a number or a texture); none: a smooth surface.
        alpha: Option<toml::Value>,
        /// Anisotropic roughness along the shading frame's two tangents, instead of `alpha`.
        alpha_u: Option<toml::Value>,
        alpha_v: Option<toml::Value>,
        /// "beckmann" (the default) or "ggx".
        distribution: Option<String>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    Principled {
        base_color: Option<toml::Value>,
        roughness: Option<toml::Value>,
        anisotropic: Option<toml::Value>,
        metallic: Option<toml::Value>,
        spec_trans: Option<toml::Value>,
        specular: Option<f32>,
        eta: Option<f32>,
        spec_tint: Option<toml::Value>,
        sheen: Option<toml::Value>,
        sheen_tint: Option<toml::Value>,
        flatness: Option<toml::Value>,
        clearcoat: Option<toml::Value>,
        clearcoat_gloss: Option<toml::Value>,
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
    Coating {
        reflectance: [f32; 3],
        transmittance: [f32; 3],
        opacity: Option<toml::Value>,
        back: Option<String>,
    },
}

fn ones() -> [f32; 3] {
    [1.0; 3]
}

fn one() -> f32 {
    1.0
}

/// One scene object: exactly one shape, a material and optionally emission.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ObjectSection {
    pub name: Option<String>,
    pub material: Spanned<String>,
    pub emission: Option<Spanned<[f32; 3]>>,
    /// An image file (sRGB where its samples are integers) relative to the scene file that multiplies `emission`
    /// (default 1 with a texture).
    pub emission_texture: Option<Spanned<String>>,
    pub mesh: Option<Spanned<String>>,
    pub quad: Option<Spanned<QuadSection>>,
    #[serde(rename = "box")]
    pub box_shape: Option<Spanned<BoxSection>>,
    pub sphere: Option<Spanned<SphereSection>>,
    pub lens_surface: Option<Spanned<LensSurfaceSection>>,
    pub annulus: Option<Spanned<AnnulusSection>>,
}

/// A parallelogram: corner and two edges; the front face is along edge1 × edge2.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct QuadSection {
    pub corner: [f32; 3],
    pub edge1: [f32; 3],
    pub edge2: [f32; 3],
}

/// An axis-aligned box with outward faces.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct BoxSection {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// An analytic sphere.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct SphereSection {
    pub center: [f32; 3],
    pub radius: f32,
}

/// An analytic spherical (or flat, radius 0) lens surface with a circular aperture.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct LensSurfaceSection {
    pub vertex: [f32; 3],
    pub axis: [f32; 3],
    pub curvature_radius: f32,
    pub aperture_radius: f32,
}

/// A flat ring (aperture stop, lens mount): centre, axis and the radii of the hole and of the rim.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct AnnulusSection {
    pub center: [f32; 3],
    pub axis: [f32; 3],
    pub inner_radius: f32,
    pub outer_radius: f32,
}

/// A point, spot, environment or sun light.
#[derive(Deserialize, Debug)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum LightSection {
    /// Light from every direction: an equirectangular map (`filename`) or a constant `radiance`.
    Environment {
        /// An OpenEXR, Radiance HDR or PFM file of linear radiance (PNG and JPEG are decoded from sRGB), relative
        /// to the scene file.
        filename: Option<String>,
        /// A constant radiance instead of a map.
        radiance: Option<[f32; 3]>,
        /// Multiplies the map's (or the constant's) radiance; default 1.
        scale: Option<f32>,
        /// The rotation from the map's frame to the world, as three rows; default the identity.
        to_world: Option<[[f32; 3]; 3]>,
    },
    /// A distant light: the sun.
    #[serde(alias = "directional")]
    Sun {
        /// The direction the light travels (from the sun into the scene).
        direction: [f32; 3],
        /// Irradiance on a plane facing the sun (W/m²).
        irradiance: [f32; 3],
        /// The sun disc's angular radius in degrees; default 0 (a delta direction, hard shadows).
        angular_radius_deg: Option<f32>,
    },
    Point {
        position: [f32; 3],
        intensity: [f32; 3],
    },
    Spot {
        position: [f32; 3],
        direction: [f32; 3],
        intensity: [f32; 3],
        cone_angle_deg: f32,
        #[serde(default)]
        falloff_start_deg: Option<f32>,
    },
}
