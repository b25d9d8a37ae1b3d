//! `<spectrum>` values and their conversion to RGB as Mitsuba 3's RGB variants (`scalar_rgb`) do it.
//!
//! Mitsuba integrates a spectrum given as wavelength:value pairs against the CIE 1931 colour-matching
//! functions on 1000 evenly spaced wavelengths from 360 to 830 nm (linear interpolation between the pairs,
//! zero outside them), normalised so that a unit spectrum has luminance 1, and maps XYZ to linear sRGB. What
//! differs is the use: a reflectance is weighted by the D65 illuminant (white reflects white) and clamped to
//! [0, 1]; other unitless quantities (a conductor's `eta` and `k`) are weighted by D65 and only their
//! negative parts clamped; an emitter's spectrum is not weighted by D65 and its negative parts are clamped. A
//! uniform value is that value in every channel, unclamped, except in an emitter, where Mitsuba gives it the
//! sRGB colour of XYZ = (v, v, v), which is not grey. Which use applies follows from the parameter's name and
//! place (`SpectrumUse::for_parameter`). The test `spectra_convert_to_rgb_as_mitsuba_does`
//! (shared/tests/suite/mitsuba_reader.rs) checks this against values Mitsuba 3.9 printed
//! (`scripts/mitsuba/spectrum-cases`).

/// A `<spectrum>` value as written.
#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    /// One value at every wavelength (`value="0.5"`).
    Uniform(f64),
    /// Wavelengths in nm, strictly increasing (at least two), with a value at each.
    Sampled { wavelengths: Vec<f64>, values: Vec<f64> },
}

/// What a spectrum describes, which decides how Mitsuba turns it into RGB.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpectrumUse {
    /// A reflectance or transmittance (a BSDF's or texture's colour): a sampled spectrum is D65-weighted and
    /// clamped to [0, 1].
    Reflectance,
    /// A unitless quantity that may exceed 1 (a conductor's `eta`, `k`): D65-weighted, negatives clamped to 0.
    Unbounded,
    /// Emitted radiance, intensity or irradiance: not D65-weighted, negatives clamped to 0.
    Emission,
}

impl SpectrumUse {
    /// The use Mitsuba gives a spectrum parameter called `name` (directly inside an `<emitter>` or not): the
    /// names `eta`, `k`, `int_ior`, `ext_ior` and `sigma_t` are unbounded everywhere, other parameters of an
    /// emitter are emission, and the rest reflectances.
    pub fn for_parameter(name: &str, in_emitter: bool) -> SpectrumUse {
        match name {
            "eta" | "k" | "int_ior" | "ext_ior" | "sigma_t" => SpectrumUse::Unbounded,
            _ if in_emitter => SpectrumUse::Emission,
            _ => SpectrumUse::Reflectance,
        }
    }
}

impl Spectrum {
    /// Parses a `value` attribute: one number, or comma- or space-separated `wavelength:value` pairs with
    /// increasing wavelengths, as Mitsuba accepts them.
    pub fn parse(text: &str) -> Result<Spectrum, String> {
        let tokens: Vec<&str> = text.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).collect();
        if tokens.len() == 1 && !tokens[0].contains(':') {
            let value = parse_finite(tokens[0])
                .ok_or_else(|| format!("\"{text}\" is neither a number nor wavelength:value pairs"))?;
            return Ok(Spectrum::Uniform(value));
        }
        if tokens.is_empty() {
            return Err("the value is empty: give a number or wavelength:value pairs".into());
        }
        let mut wavelengths = Vec::with_capacity(tokens.len());
        let mut values = Vec::with_capacity(tokens.len());
        for token in &tokens {
            let pair = token.split_once(':').and_then(|(w, v)| Some((parse_finite(w)?, parse_finite(v)?)));
            let Some((wavelength, value)) = pair else {
                return Err(format!("\"{token}\" is not a wavelength:value pair (e.g. \"400:0.5, 700:0.2\")"));
            };
            if let Some(&last) = wavelengths.last() {
                if wavelength <= last {
                    return Err(format!("wavelength {wavelength} follows {last}: wavelengths must increase"));
                }
            }
            wavelengths.push(wavelength);
            values.push(value);
        }
        if wavelengths.len() < 2 {
            return Err("a sampled spectrum needs at least two wavelength:value pairs".into());
        }
        Ok(Spectrum::Sampled { wavelengths, values })
    }

    /// The linear sRGB colour Mitsuba 3's RGB variants use for this spectrum in the given use.
    pub fn to_rgb(&self, usage: SpectrumUse) -> [f64; 3] {
        let rgb = match self {
            Spectrum::Uniform(value) if usage != SpectrumUse::Emission => return [*value; 3],
            // Mitsuba maps a uniform emission to the sRGB of XYZ = (1, 1, 1), scaled, with no integral.
            Spectrum::Uniform(value) => xyz_to_srgb([1.0; 3]).map(|c| c * value),
            Spectrum::Sampled { wavelengths, values } => {
                integrate_to_srgb(wavelengths, values, usage != SpectrumUse::Emission)
            }
        };
        match usage {
            SpectrumUse::Reflectance => rgb.map(|c| c.clamp(0.0, 1.0)),
            SpectrumUse::Unbounded | SpectrumUse::Emission => rgb.map(|c| c.max(0.0)),
        }
    }
}

fn parse_finite(text: &str) -> Option<f64> {
    text.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

const CIE_MIN: f64 = 360.0;
const CIE_MAX: f64 = 830.0;
const CIE_SAMPLES: usize = 95;
/// The integral of the CIE Y curve over the table in nm: dividing by it gives a unit spectrum luminance 1.
const CIE_Y_INTEGRAL: f64 = 106.750_259_399_414_06;
/// The integral of the CIE Y curve weighted by the D65 table below: dividing by it normalises D65 to luminance 1.
const D65_Y_INTEGRAL: f64 = 98.99741751876255;
/// Wavelengths at which the spectrum is evaluated in the integral, as Mitsuba does.
const INTEGRATION_STEPS: usize = 1000;

/// Integrates the piecewise-linear spectrum against the colour-matching functions and maps XYZ to linear sRGB.
fn integrate_to_srgb(wavelengths: &[f64], values: &[f64], weight_by_d65: bool) -> [f64; 3] {
    let (first, last) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    let mut xyz = [0.0f64; 3];
    for i in 0..INTEGRATION_STEPS {
        let w = CIE_MIN + (i as f64 / (INTEGRATION_STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        if w < first || w > last {
            continue;
        }
        // The interval [w0, w1] holding w; the last one also holds its upper end.
        let index = wavelengths.partition_point(|&x| x <= w).clamp(1, wavelengths.len() - 1) - 1;
        let (w0, w1) = (wavelengths[index], wavelengths[index + 1]);
        let (v0, v1) = (values[index], values[index + 1]);
        let value = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1);
        let weight = if weight_by_d65 { table_at(&D65, w) / D65_Y_INTEGRAL } else { 1.0 };
        let cmf = [table_at(&CIE_X, w), table_at(&CIE_Y, w), table_at(&CIE_Z, w)];
        for (sum, c) in xyz.iter_mut().zip(cmf) {
            *sum += c * value * weight;
        }
    }
    let scale = (CIE_MAX - CIE_MIN) / INTEGRATION_STEPS as f64 / CIE_Y_INTEGRAL;
    xyz_to_srgb(xyz.map(|c| c * scale))
}

/// CIE XYZ to linear sRGB (D65 white), with Mitsuba's coefficients.
fn xyz_to_srgb([x, y, z]: [f64; 3]) -> [f64; 3] {
    [
        3.240479 * x - 1.537150 * y - 0.498535 * z,
        -0.969256 * x + 1.875991 * y + 0.041556 * z,
        0.055648 * x - 0.204043 * y + 1.057311 * z,
    ]
}

/// A table sampled every 5 nm from 360 to 830 nm, linearly interpolated at `w` (zero outside).
fn table_at(table: &[f32; CIE_SAMPLES], w: f64) -> f64 {
    if !(CIE_MIN..=CIE_MAX).contains(&w) {
        return 0.0;
    }
    // Interpolation in single precision, as Mitsuba's tables are evaluated.
    let t = ((w - CIE_MIN) * ((CIE_SAMPLES - 1) as f64 / (CIE_MAX - CIE_MIN))) as f32;
    let i0 = (t as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i0 as f32;
    ((1.0 - w1) * table[i0] + w1 * table[i0 + 1]) as f64
}

// The CIE 1931 2° colour-matching functions and the CIE D65 illuminant (relative, 100 at 560 nm), every 5 nm
// from 360 to 830 nm: the tables Mitsuba 3 uses.
const CIE_X: [f32; CIE_SAMPLES] = [
    0.0001299,
    0.0002321,
    0.0004149,
    0.0007416,
    0.001368,
    0.002236,
    0.004243,
    0.00765,
    0.01431,
    0.02319,
    0.04351,
    0.07763,
    0.13438,
    0.21477,
    0.2839,
    0.3285,
    0.34828,
    0.34806,
    0.3362,
    0.3187,
    0.2908,
    0.2511,
    0.19536,
    0.1421,
    0.09564,
    0.05795001,
    0.03201,
    0.0147,
    0.0049,
    0.0024,
    0.0093,
    0.0291,
    0.06327,
    0.1096,
    0.1655,
    0.2257499,
    0.2904,
    0.3597,
    0.4334499,
    0.5120501,
    0.5945,
    0.6784,
    0.7621,
    0.8425,
    0.9163,
    0.9786,
    1.0263,
    1.0567,
    1.0622,
    1.0456,
    1.0026,
    0.9384,
    0.8544499,
    0.7514,
    0.6424,
    0.5419,
    0.4479,
    0.3608,
    0.2835,
    0.2187,
    0.1649,
    0.1212,
    0.0874,
    0.0636,
    0.04677,
    0.0329,
    0.0227,
    0.01584,
    0.01135916,
    0.008110916,
    0.005790346,
    0.004109457,
    0.002899327,
    0.00204919,
    0.001439971,
    0.0009999493,
    0.0006900786,
    0.0004760213,
    0.0003323011,
    0.0002348261,
    0.0001661505,
    0.000117413,
    0.00008307527,
    0.00005870652,
    0.00004150994,
    0.00002935326,
    0.00002067383,
    0.00001455977,
    0.00001025398,
    0.000007221456,
    0.000005085868,
    0.000003581652,
    0.000002522525,
    0.000001776509,
    0.000001251141,
];
const CIE_Y: [f32; CIE_SAMPLES] = [
    0.000003917,
    0.000006965,
    0.00001239,
    0.00002202,
    0.000039,
    0.000064,
    0.00012,
    0.000217,
    0.000396,
    0.00064,
    0.00121,
    0.00218,
    0.004,
    0.0073,
    0.0116,
    0.01684,
    0.023,
    0.0298,
    0.038,
    0.048,
    0.06,
    0.0739,
    0.09098,
    0.1126,
    0.13902,
    0.1693,
    0.20802,
    0.2586,
    0.323,
    0.4073,
    0.503,
    0.6082,
    0.71,
    0.7932,
    0.862,
    0.9148501,
    0.954,
    0.9803,
    0.9949501,
    1.0,
    0.995,
    0.9786,
    0.952,
    0.9154,
    0.87,
    0.8163,
    0.757,
    0.6949,
    0.631,
    0.5668,
    0.503,
    0.4412,
    0.381,
    0.321,
    0.265,
    0.217,
    0.175,
    0.1382,
    0.107,
    0.0816,
    0.061,
    0.04458,
    0.032,
    0.0232,
    0.017,
    0.01192,
    0.00821,
    0.005723,
    0.004102,
    0.002929,
    0.002091,
    0.001484,
    0.001047,
    0.00074,
    0.00052,
    0.0003611,
    0.0002492,
    0.0001719,
    0.00012,
    0.0000848,
    0.00006,
    0.0000424,
    0.00003,
    0.0000212,
    0.00001499,
    0.0000106,
    0.0000074657,
    0.0000052578,
    0.0000037029,
    0.0000026078,
    0.0000018366,
    0.0000012934,
    0.00000091093,
    0.00000064153,
    0.00000045181,
];
const CIE_Z: [f32; CIE_SAMPLES] = [
    0.0006061,
    0.001086,
    0.001946,
    0.003486,
    0.006450001,
    0.01054999,
    0.02005001,
    0.03621,
    0.06785001,
    0.1102,
    0.2074,
    0.3713,
    0.6456,
    1.0390501,
    1.3856,
    1.62296,
    1.74706,
    1.7826,
    1.77211,
    1.7441,
    1.6692,
    1.5281,
    1.28764,
    1.0419,
    0.8129501,
    0.6162,
    0.46518,
    0.3533,
    0.272,
    0.2123,
    0.1582,
    0.1117,
    0.07824999,
    0.05725001,
    0.04216,
    0.02984,
    0.0203,
    0.0134,
    0.008749999,
    0.005749999,
    0.0039,
    0.002749999,
    0.0021,
    0.0018,
    0.001650001,
    0.0014,
    0.0011,
    0.001,
    0.0008,
    0.0006,
    0.00034,
    0.00024,
    0.00019,
    0.0001,
    0.00004999999,
    0.00003,
    0.00002,
    0.00001,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
];
const D65: [f32; CIE_SAMPLES] = [
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015, 82.7549, 87.1204, 91.486, 92.4589, 93.4318,
    90.057, 86.6823, 95.7736, 104.865, 110.936, 117.008, 117.41, 117.812, 116.336, 114.861, 115.392, 115.923, 112.367,
    108.811, 109.082, 109.354, 108.578, 107.802, 106.296, 104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046,
    102.023, 100.0, 98.1671, 96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459, 90.0062, 89.8026, 89.5991, 88.6489,
    87.6987, 85.4936, 83.2886, 83.4939, 83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462, 82.2778, 80.281, 78.2842,
    74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765, 61.604, 65.7448, 69.8856, 72.4863, 75.087, 69.3398,
    63.5927, 55.0054, 46.4182, 56.6118, 66.8054, 65.0941, 63.3828, 63.8434, 64.304, 61.8779, 59.4519, 55.7054, 51.959,
    54.6998, 57.4406, 58.8765, 60.3125,
];
