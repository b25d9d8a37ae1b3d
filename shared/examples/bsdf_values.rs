//! photonfarm's BSDF values for the Mitsuba 3 cross-check (scripts/mitsuba/bsdf-compare, docs/materials.md).
//! Reads one query a line on stdin and answers one line on stdout:
//!
//! - `eval SPEC | wo | wi` → f(wo, wi)·|cos θ_i| (three channels) and pdf(wo, wi), in camera (radiance) mode;
//! - `delta SPEC | wo` → for every delta continuation: wi (three numbers) and weight × probability (three),
//!   the energy the lobe carries; `;` between continuations.
//!
//! Directions are three numbers in the family's local frame (z the normal on the arriving side). SPEC is a
//! family and `key=value` parameters with Mitsuba 3's names: `diffuse reflectance=R,G,B`; `conductor
//! material=Au` or `eta=R,G,B k=R,G,B`, with `distribution=ggx|beckmann alpha_u= alpha_v=` when rough;
//! `dielectric`, `roughdielectric` (with the roughness), `thindielectric` with `int_ior= ext_ior=` and `side=inside`
//! for the back; `plastic diffuse_reflectance= int_ior= ext_ior= nonlinear=true` with `distribution= alpha=`
//! when rough; `principled` with its parameter names and `side=inside`.
//!
//! `cargo run --release -p photonfarm --example bsdf_values < queries.txt`

use glam::Vec3;
use photonfarm::bsdf::conductor::ConductorFresnel;
use photonfarm::bsdf::microfacet::{Distribution, Microfacet};
use photonfarm::bsdf::plastic::Coat;
use photonfarm::bsdf::principled::{eta_of_specular, PrincipledParams};
use photonfarm::bsdf::{
    Conductor, DeltaBranches, Dielectric, Diffuse, Model, Plastic, Principled, RoughDielectric, ThinDielectric,
    Transport,
};
use photonfarm::color::Rgb;
use photonfarm::spectrum::RefractiveIndex;
use std::collections::HashMap;
use std::io::{BufRead, Write};

type Error = Box<dyn std::error::Error>;

struct Params(HashMap<String, String>);

impl Params {
    fn num(&self, key: &str, default: f32) -> Result<f32, Error> {
        self.0.get(key).map_or(Ok(default), |v| v.parse().map_err(|e| format!("{key}={v}: {e}").into()))
    }

    fn rgb(&self, key: &str, default: f32) -> Result<Rgb, Error> {
        let Some(v) = self.0.get(key) else { return Ok(Rgb::splat(default)) };
        let c: Vec<f32> = v.split(',').map(str::parse).collect::<Result<_, _>>().map_err(|e| format!("{key}: {e}"))?;
        match c[..] {
            [g] => Ok(Rgb::splat(g)),
            [r, g, b] => Ok(Rgb::new(r, g, b)),
            _ => Err(format!("{key}={v}: one or three numbers").into()),
        }
    }

    fn inside(&self) -> bool {
        self.0.get("side").is_some_and(|s| s == "inside")
    }

    /// The microfacet roughness if a distribution is given (Mitsuba's default distribution is Beckmann).
    fn microfacet(&self, default_alpha: f32) -> Result<Option<Microfacet>, Error> {
        let Some(d) = self.0.get("distribution") else { return Ok(None) };
        let d = match d.as_str() {
            "ggx" => Distribution::Ggx,
            "beckmann" => Distribution::Beckmann,
            other => return Err(format!("distribution {other}").into()),
        };
        let alpha = self.num("alpha", default_alpha)?;
        Ok(Some(Microfacet::new(d, self.num("alpha_u", alpha)?, self.num("alpha_v", alpha)?)))
    }

    /// (η on the arriving side, η across), Mitsuba's defaults BK7 in air.
    fn indices(&self) -> Result<(f32, f32), Error> {
        let (int, ext) = (self.num("int_ior", 1.5046)?, self.num("ext_ior", 1.000277)?);
        Ok(if self.inside() { (int, ext) } else { (ext, int) })
    }
}

fn model(spec: &str) -> Result<Model, Error> {
    let mut words = spec.split_whitespace();
    let family = words.next().ok_or("empty spec")?;
    let mut map = HashMap::new();
    for w in words {
        let (k, v) = w.split_once('=').ok_or_else(|| format!("`{w}` is not key=value"))?;
        map.insert(k.to_string(), v.to_string());
    }
    let p = Params(map);
    let c = RefractiveIndex::constant;
    Ok(match family {
        "diffuse" => Model::Diffuse(Diffuse { reflectance: p.rgb("reflectance", 0.5)? }),
        "conductor" => {
            let fresnel = match p.0.get("material") {
                Some(name) => ConductorFresnel::named(name)?,
                None => ConductorFresnel::Complex { eta: p.rgb("eta", 0.0)?, k: p.rgb("k", 1.0)? },
            };
            Model::Conductor(Conductor {
                fresnel,
                specular: p.rgb("specular_reflectance", 1.0)?,
                roughness: p.microfacet(0.1)?,
            })
        }
        "dielectric" => {
            let (o, t) = p.indices()?;
            Model::Dielectric(Dielectric { eta_o: c(o), eta_t: c(t), anti_reflection: false })
        }
        "roughdielectric" => {
            let (o, t) = p.indices()?;
            Model::RoughDielectric(RoughDielectric {
                eta_o: c(o),
                eta_t: c(t),
                microfacet: p.microfacet(0.1)?.ok_or("roughdielectric needs a distribution")?,
                specular_reflectance: p.rgb("specular_reflectance", 1.0)?,
                specular_transmittance: p.rgb("specular_transmittance", 1.0)?,
            })
        }
        "thindielectric" => Model::ThinDielectric(ThinDielectric {
            int_ior: c(p.num("int_ior", 1.5046)?),
            ext_ior: c(p.num("ext_ior", 1.000277)?),
            specular_reflectance: p.rgb("specular_reflectance", 1.0)?,
            specular_transmittance: p.rgb("specular_transmittance", 1.0)?,
        }),
        "plastic" => {
            let eta = p.num("int_ior", 1.49)? / p.num("ext_ior", 1.000277)?;
            let coat = match p.microfacet(0.1)? {
                Some(m) => Coat::rough(m.distribution, m.alpha_x, eta),
                None => Coat::Smooth,
            };
            let nonlinear = p.0.get("nonlinear").is_some_and(|v| v == "true");
            Model::Plastic(Plastic::new(
                p.rgb("diffuse_reflectance", 0.5)?,
                p.rgb("specular_reflectance", 1.0)?,
                eta,
                nonlinear,
                coat,
            ))
        }
        "principled" => {
            let d = PrincipledParams::default();
            let eta = match (p.0.get("eta"), p.0.get("specular")) {
                (Some(_), _) => p.num("eta", d.eta)?,
                (None, Some(_)) => eta_of_specular(p.num("specular", 0.5)?),
                (None, None) => d.eta,
            };
            let params = PrincipledParams {
                base_color: p.rgb("base_color", 0.5)?,
                roughness: p.num("roughness", d.roughness)?,
                anisotropic: p.num("anisotropic", d.anisotropic)?,
                metallic: p.num("metallic", d.metallic)?,
                spec_trans: p.num("spec_trans", d.spec_trans)?,
                eta,
                spec_tint: p.num("spec_tint", d.spec_tint)?,
                sheen: p.num("sheen", d.sheen)?,
                sheen_tint: p.num("sheen_tint", d.sheen_tint)?,
                flatness: p.num("flatness", d.flatness)?,
                clearcoat: p.num("clearcoat", d.clearcoat)?,
                clearcoat_gloss: p.num("clearcoat_gloss", d.clearcoat_gloss)?,
                ..d
            };
            Model::Principled(Principled::new(&params, p.inside()))
        }
        other => return Err(format!("unknown family `{other}`").into()),
    })
}

fn vec3(s: &str) -> Result<Vec3, Error> {
    let v: Vec<f32> = s.split_whitespace().map(str::parse).collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("`{s}` is not three numbers").into()),
    }
}

fn answer(line: &str) -> Result<String, Error> {
    let (command, rest) = line.split_once(' ').ok_or("no command")?;
    let parts: Vec<&str> = rest.split('|').collect();
    let m = model(parts[0])?;
    let s = m.scatter().ok_or("no family")?;
    match (command, &parts[1..]) {
        ("eval", [wo, wi]) => {
            let (wo, wi) = (vec3(wo)?, vec3(wi)?);
            let f = s.eval(wo, wi, Transport::Radiance, false) * wi.z.abs();
            Ok(format!("{:e} {:e} {:e} {:e}", f.x, f.y, f.z, s.pdf(wo, wi)))
        }
        ("delta", [wo]) => {
            let wo = vec3(wo)?;
            let branches = match m {
                Model::Dielectric(d) => d.delta_branches(wo),
                Model::ThinDielectric(t) => t.delta_branches(wo),
                Model::Plastic(p) => p.delta_branches(wo),
                Model::Conductor(c) => c.delta_branches(wo),
                _ => DeltaBranches::default(),
            };
            let out: Vec<String> = branches
                .iter()
                .map(|(b, p)| {
                    let w = b.weight * *p;
                    format!("{} {} {} {:e} {:e} {:e}", b.wi.x, b.wi.y, b.wi.z, w.x, w.y, w.z)
                })
                .collect();
            Ok(out.join(";"))
        }
        _ => Err(format!("cannot read `{line}`").into()),
    }
}

fn main() -> Result<(), Error> {
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for line in std::io::stdin().lock().lines() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        writeln!(out, "{}", answer(&line).map_err(|e| format!("{line}: {e}"))?)?;
    }
    Ok(())
}
