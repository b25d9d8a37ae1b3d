//! `coordinator reference`: a long render kept as a scene's reference image, against which every run and the
//! bench measure their true error. The path tracer by default; PBPM where the path tracer cannot converge
//! (caustics seen through glass, point lights behind specular surfaces).

use crate::cli::ReferenceArgs;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;

pub fn run(args: ReferenceArgs) -> Result<()> {
    if !(args.time.is_finite() && args.time > 0.0) {
        bail!("--time must be a positive number of seconds");
    }
    if !args.scene.is_file() {
        bail!("no scene file {}", args.scene.display());
    }
    let stem = args.scene.file_stem().context("the scene path has no file name")?.to_string_lossy().into_owned();
    // Named by estimator, which is what decides what the reference can show; the record keeps the method.
    let estimator = args.method.estimator().name();
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let (exr, json) =
        (args.out.join(format!("{stem}-{estimator}.exr")), args.out.join(format!("{stem}-{estimator}.json")));
    if exr.exists() && !args.force {
        bail!("{} exists; pass --force to replace it", exr.display());
    }
    let run_dir = PathBuf::from("out").join(format!("reference-{stem}-{estimator}"));
    let _ = std::fs::remove_dir_all(&run_dir);
    let mut command = vec![
        "render".to_string(),
        args.scene.display().to_string(),
        "--method".into(),
        args.method.name().into(),
        "--time".into(),
        args.time.to_string(),
        "--seed".into(),
        args.seed.to_string(),
    ];
    if let Some(t) = &args.topology {
        command.extend(["--topology".into(), t.clone()]);
    }
    if let Some(r) = args.radius_scale {
        command.extend(["--radius-scale".into(), r.to_string()]);
    }
    let exe = std::env::current_exe().context("cannot find this program")?;
    tracing::info!("rendering the reference: coordinator {}", command.join(" "));
    let status = std::process::Command::new(exe)
        .args(&command)
        .arg("--out")
        .arg(&run_dir)
        .status()
        .context("cannot start the render")?;
    if !status.success() {
        bail!("the reference render failed ({status}); what it finished is in {}", run_dir.display());
    }
    let record_path = run_dir.join("run.json");
    let mut record: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&record_path).with_context(|| format!("cannot read {}", record_path.display()))?,
    )?;
    // A reference's record keeps how to remake it, but not its per-step history (thousands of phases).
    record["command"] = serde_json::Value::String(format!("coordinator {}", command.join(" ")));
    if let Some(map) = record.as_object_mut() {
        map.remove("history");
    }
    std::fs::copy(run_dir.join("image.exr"), &exr).with_context(|| format!("cannot write {}", exr.display()))?;
    std::fs::write(&json, serde_json::to_vec_pretty(&record)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    say!(
        "wrote {} and {} (δ {:.2}% over pixels that do not see a light directly)",
        exr.display(),
        json.display(),
        100.0 * record["error"]["delta_unlit"].as_f64().unwrap_or(f64::NAN)
    );
    Ok(())
}
