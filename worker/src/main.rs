//! `worker`: the rendering process. A coordinator starts one per NUMA node (`worker join`), or a server runs it
//! as a daemon that coordinators dial (`worker serve`).

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use photonfarm::protocol::auth::Secret;
use photonfarm::protocol::tls::{Tls, Transport};
use photonfarm::protocol::Role;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use worker::files::FileCache;
use worker::link::{serve_job, LinkOptions};

#[derive(Parser)]
#[command(name = "worker", version, about = "photonfarm's rendering process")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args)]
struct SecretArgs {
    /// File holding the shared secret (at least 16 bytes); otherwise $PHOTONFARM_SECRET.
    #[arg(long)]
    secret_file: Option<PathBuf>,
    /// Allow links to other machines without TLS and without a secret (anyone who can reach the port can
    /// then use this machine, and scenes and images cross the network in the clear).
    #[arg(long)]
    insecure: bool,
    /// Folder with the job CA's ca.pem, worker.pem, worker.key (and secret) from `coordinator keys init`:
    /// the link runs over mutually authenticated TLS (required off loopback unless --insecure).
    #[arg(long, value_name = "DIR")]
    tls_dir: Option<PathBuf>,
    /// The name this worker gives the coordinator (default: the host name).
    #[arg(long)]
    name: Option<String>,
    /// Render this many times slower than the machine can (the worker sleeps after each round): a straggler,
    /// to test how a run copes with one.
    #[arg(long, default_value_t = 1.0, value_parser = parse_slowdown)]
    slowdown: f64,
}

fn parse_slowdown(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(f) if f.is_finite() && f >= 1.0 => Ok(f),
        _ => Err(format!("'{text}' is not a slowdown factor of at least 1 (e.g. 3)")),
    }
}

#[derive(Subcommand)]
enum Command {
    /// Dial a coordinator and render its job (what a coordinator or a cluster scheduler starts).
    Join {
        /// The coordinator's address, e.g. 10.0.0.5:7878.
        addr: String,
        #[command(flatten)]
        secret: SecretArgs,
    },
    /// Listen for coordinators and render their jobs one after another (a render server's daemon).
    Serve {
        /// Address to listen on, e.g. 0.0.0.0:7879.
        #[arg(long)]
        listen: SocketAddr,
        #[command(flatten)]
        secret: SecretArgs,
    },
}

fn secret(args: &SecretArgs, loopback: bool) -> Result<Secret> {
    Ok(Secret::resolve(args.secret_file.as_deref(), args.tls_dir.as_deref(), args.insecure || loopback)?)
}

/// TLS with the `--tls-dir` keys; plaintext only on loopback or with an explicit `--insecure`.
fn transport(args: &SecretArgs, loopback: bool) -> Result<Transport> {
    if let Some(dir) = &args.tls_dir {
        return Ok(Transport::Tls(Tls::load(dir, Role::Worker)?));
    }
    if args.insecure || loopback {
        return Ok(Transport::Plain);
    }
    bail!(
        "a link that is not loopback is encrypted: give --tls-dir DIR with the job's ca.pem, worker.pem and \
         worker.key (from `coordinator keys init`), or --insecure to send scenes and images in the clear"
    )
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    worker::logging::init();
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            tracing::error!("cannot start the network runtime: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(cli)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

async fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Join { addr, secret: s } => {
            let addrs: Vec<SocketAddr> = tokio::net::lookup_host(&addr)
                .await
                .with_context(|| format!("cannot resolve the coordinator address {addr}"))?
                .collect();
            let loopback = !addrs.is_empty() && addrs.iter().all(|a| a.ip().is_loopback());
            let mut opts =
                LinkOptions::new(s.name.clone().unwrap_or_else(worker::machine::hostname), secret(&s, loopback)?);
            let transport = transport(&s, loopback)?;
            opts.slowdown = s.slowdown;
            // The coordinator may still be starting: retry for a while.
            let deadline = Instant::now() + Duration::from_secs(15);
            let stream = loop {
                match tokio::net::TcpStream::connect(&addrs[..]).await {
                    Ok(s) => break s,
                    Err(_) if Instant::now() < deadline => tokio::time::sleep(Duration::from_millis(200)).await,
                    Err(e) => return Err(e).with_context(|| format!("cannot reach the coordinator at {addr}")),
                }
            };
            let conn = transport.connect(stream).await.with_context(|| format!("cannot set up the link to {addr}"))?;
            let outcome = serve_job(conn, &opts, &mut FileCache::for_one_job()).await?;
            tracing::info!(
                worker = %opts.name,
                job = %outcome.job,
                coordinator = %outcome.coordinator,
                "job done, {} snapshots sent, {} acknowledged",
                outcome.snapshots_sent,
                outcome.snapshots_acked
            );
            Ok(())
        }
        Command::Serve { listen, secret: s } => {
            let mut opts = LinkOptions::new(
                s.name.clone().unwrap_or_else(worker::machine::hostname),
                secret(&s, listen.ip().is_loopback())?,
            );
            opts.slowdown = s.slowdown;
            let transport = transport(&s, listen.ip().is_loopback())?;
            let listener =
                tokio::net::TcpListener::bind(listen).await.with_context(|| format!("cannot listen on {listen}"))?;
            tracing::info!(worker = %opts.name, "listening on {}", listener.local_addr()?);
            let mut cache = FileCache::kept_between_jobs();
            loop {
                let (stream, peer) = listener.accept().await.context("accept failed")?;
                if opts.secret.is_insecure() && !peer.ip().is_loopback() && !s.insecure {
                    tracing::warn!(worker = %opts.name, "refused {peer}: no secret is set and the link is not loopback");
                    continue;
                }
                let conn = match transport.accept(stream).await {
                    Ok(c) => c,
                    Err(e) => {
                        tracing::warn!(worker = %opts.name, "refused {peer}: {e}");
                        continue;
                    }
                };
                match serve_job(conn, &opts, &mut cache).await {
                    Ok(o) => tracing::info!(
                        worker = %opts.name,
                        job = %o.job,
                        coordinator = %o.coordinator,
                        "job from {peer} done, {} snapshots sent, {} acknowledged",
                        o.snapshots_sent,
                        o.snapshots_acked
                    ),
                    Err(e) => tracing::warn!(worker = %opts.name, "link with {peer} ended: {e}"),
                }
            }
        }
    }
}
