//! Linear RGB radiometric quantities (Rec.709 primaries), the colour model of every non-spectral scene.

/// Linear RGB triple: radiance, flux, throughput or reflectance depending on context.
pub type Rgb = glam::Vec3;

/// Rec.709 luminance weights: the scalar that error estimates and light selection work with.
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Luminance in f64, for the running sums of squares where f32 would lose the small terms.
pub fn luminance_f64(c: [f64; 3]) -> f64 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}
