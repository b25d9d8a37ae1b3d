//! Watching a render: the live page of `render --serve` over HTTP (image, state, stop, the secret) and in a
//! real headless browser, and the layers streamed to a (fake) tev.

use end_to_end::{binary, cornell_at, repo_root, scratch_dir};
use photonfarm::image_io::exr_file::read_exr;
use photonfarm::image_io::preview::{auto_exposure, tonemap_rgb8};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A secret of the length `Secret` asks for.
const SECRET: &str = "live-page-test-secret-0123456789";

/// A response: status, head (lower-cased) and body.
struct Reply {
    status: u16,
    head: String,
    body: Vec<u8>,
}

impl Reply {
    fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| panic!("not JSON ({e}): {}", self.text()))
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

/// One HTTP/1.1 request over a fresh connection to 127.0.0.1:`port`.
fn http(port: u16, method: &str, path: &str, headers: &[(&str, &str)], body: &str) -> Reply {
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("the page accepts connections");
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut request = format!("{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n");
    for (k, v) in headers {
        request.push_str(&format!("{k}: {v}\r\n"));
    }
    request.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    s.write_all(request.as_bytes()).unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").expect("an HTTP head");
    let head = String::from_utf8_lossy(&raw[..split]).to_lowercase();
    let status = head.split(' ').nth(1).and_then(|c| c.parse().ok()).expect("a status code");
    let mut body = raw[split + 4..].to_vec();
    if head.contains("transfer-encoding: chunked") {
        body = unchunk(&body);
    }
    Reply { status, head, body }
}

fn unchunk(mut raw: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(end) = raw.windows(2).position(|w| w == b"\r\n") {
        let size = usize::from_str_radix(std::str::from_utf8(&raw[..end]).unwrap().trim(), 16).unwrap();
        if size == 0 {
            break;
        }
        out.extend_from_slice(&raw[end + 2..end + 2 + size]);
        raw = &raw[end + 4 + size..];
    }
    out
}

/// Decodes a PNG into (width, height, RGB bytes).
fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().expect("a valid PNG");
    let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buffer).expect("a valid PNG");
    buffer.truncate(info.buffer_size());
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        other => panic!("an 8-bit RGB(A) PNG, not {other:?}"),
    };
    let rgb = buffer.chunks_exact(channels).flat_map(|p| [p[0], p[1], p[2]]).collect();
    (info.width, info.height, rgb)
}

/// A render started with `--serve`, its page's port read from the line it prints.
struct Served {
    child: Child,
    port: u16,
    /// The Authorization header's value, for a page that needs the secret.
    auth: Option<String>,
    stdout: std::thread::JoinHandle<String>,
}

fn serve(scene: &Path, out: &Path, addr: &str, args: &[&str], secret: Option<&str>) -> Served {
    let mut cmd = Command::new(binary("coordinator"));
    cmd.arg("render").arg(scene).arg("--out").arg(out).args(["--quiet", "--serve", addr, "--serve-linger", "3"]);
    cmd.args(args);
    cmd.env_remove("PHOTONFARM_SECRET");
    if let Some(s) = secret {
        cmd.env("PHOTONFARM_SECRET", s);
    }
    let mut child =
        cmd.current_dir(repo_root()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the coordinator");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().expect("a first line").unwrap();
    let port = first
        .strip_prefix("live page: ")
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|url| url.trim_end_matches('/').rsplit(':').next()?.parse().ok())
        .unwrap_or_else(|| panic!("the first line gives the page's URL: {first}"));
    assert!(first.contains(&out.display().to_string()), "the URL is printed with the output folder: {first}");
    let stdout = std::thread::spawn(move || lines.map_while(Result::ok).collect::<Vec<_>>().join("\n"));
    Served { child, port, auth: secret.map(|s| format!("Bearer {s}")), stdout }
}

impl Served {
    fn state(&self) -> serde_json::Value {
        let auth: Vec<(&str, &str)> = self.auth.iter().map(|a| ("Authorization", a.as_str())).collect();
        http(self.port, "GET", "/state.json", &auth, "").json()
    }

    /// Polls the state until `done` holds of it.
    fn wait_for(&self, what: &str, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let s = self.state();
            if done(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "no {what} within a minute: {s}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits for the process to end; returns its stdout after the URL line, asserting success.
    fn finish(mut self) -> String {
        let status = self.child.wait().unwrap();
        let mut err = String::new();
        self.child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
        assert!(status.success(), "{err}");
        self.stdout.join().unwrap()
    }
}

#[test]
fn the_page_serves_the_image_and_state_and_its_stop_ends_the_run_with_every_file_written() {
    let dir = scratch_dir("live-page");
    let scene = cornell_at(&dir, 48);
    let out = dir.join("out");
    // The first step is saved at once and, with a 1000 s interval, no other before the stop.
    let run =
        serve(&scene, &out, "127.0.0.1:0", &["--method", "pbpm", "--time", "120", "--save-interval", "1000"], None);
    let page = http(run.port, "GET", "/", &[], "");
    assert_eq!(page.status, 200);
    assert!(page.text().contains("<canvas") && page.text().contains("Stop the run"));
    let s = run.wait_for("second phase", |s| s["phases"].as_u64() >= Some(2) && s["delta_unlit"].is_f64());
    assert_eq!((s["state"].as_str(), s["width"].as_u64(), s["height"].as_u64()), (Some("running"), Some(48), Some(48)));
    let layers: Vec<&str> = s["layers"].as_array().unwrap().iter().map(|l| l.as_str().unwrap()).collect();
    for l in ["total", "visible_lights", "direct", "indirect", "caustic", "sem", "phases"] {
        assert!(layers.contains(&l), "{l} in {layers:?}");
        let reply = http(run.port, "GET", &format!("/image.png?layer={l}&ev=1"), &[], "");
        assert_eq!(reply.status, 200, "{l}: {}", reply.text());
        assert_eq!(decode_png(&reply.body).0, 48);
    }
    let bad = http(run.port, "GET", "/image.png?layer=beauty", &[], "");
    assert!(bad.status == 400 && bad.text().contains("beauty"), "{}", bad.text());
    assert!(s["history"].as_array().unwrap().len() >= 2 && s["rays_per_s"].as_f64().unwrap() > 0.0);
    let first_save: serde_json::Value = http(run.port, "GET", "/run.json", &[], "").json();
    assert_eq!(http(run.port, "GET", "/settings.json", &[], "").json()["method"], "pbpm");
    assert!(out.join("image.exr").exists(), "the first step was saved");

    assert_eq!(http(run.port, "POST", "/stop", &[], "").status, 202);
    let end = run.wait_for("end", |s| s["state"] == "finished");
    let exr = read_exr(&out.join("image.exr")).expect("the stop wrote image.exr");
    let total = exr.iter().find(|l| l.name == "total").unwrap();
    let exposure = auto_exposure(total);
    let reply = http(run.port, "GET", &format!("/image.png?layer=total&exposure={exposure}"), &[], "");
    let (w, h, live) = decode_png(&reply.body);
    assert_eq!((w, h), (48, 48));
    // The page's last image is made from the sums the EXR was written from (stored as f32, losslessly) with the
    // preview's tonemap: the same bytes, up to the printed exposure's last digit moving a pixel by one level.
    let file = tonemap_rgb8(total, exposure);
    let mean = |b: &[u8]| b.iter().map(|&v| f64::from(v)).sum::<f64>() / b.len() as f64;
    assert!(mean(&live) > 5.0, "the image is not black");
    assert!((mean(&live) - mean(&file)).abs() < 0.05, "page {} against EXR {}", mean(&live), mean(&file));
    assert!(live.iter().zip(&file).all(|(a, b)| a.abs_diff(*b) <= 1));

    let downloaded = http(run.port, "GET", "/run.json", &[], "");
    assert!(downloaded.head.contains("content-disposition: attachment"));
    let record: serde_json::Value = downloaded.json();
    assert_eq!(record["stop_reason"], "interrupted");
    assert_eq!(end["stop_reason"], "interrupted");
    for k in ["delta_all", "delta_unlit"] {
        assert_eq!(end[k].as_f64(), record["error"][k].as_f64(), "{k}: the page ends on run.json's δ");
    }
    assert_eq!(end["phases"], record["totals"]["phases"]);
    let phases = |r: &serde_json::Value| r["totals"]["phases"].as_u64().unwrap();
    assert!(
        phases(&first_save) < phases(&record),
        "the stop saved again: {} phases, then {}",
        phases(&first_save),
        phases(&record)
    );
    let stdout = run.finish();
    assert!(stdout.contains("interrupted: the results of every completed phase were written"), "{stdout}");
    for f in ["image.exr", "preview.png", "run.json"] {
        assert!(out.join(f).is_file(), "{f} written");
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_page_off_loopback_needs_the_secret_for_every_request_and_the_stop() {
    let dir = scratch_dir("live-secret");
    let scene = cornell_at(&dir, 32);
    let refused = Command::new(binary("coordinator"))
        .args(["render", "--method", "pbpm", "--phases", "1", "--quiet", "--serve", "0.0.0.0:0", "--out"])
        .arg(dir.join("refused"))
        .arg(&scene)
        .env_remove("PHOTONFARM_SECRET")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("not a loopback address") && err.contains("secret"), "{err}");

    let run = serve(&scene, &dir.join("out"), "0.0.0.0:0", &["--method", "pbpm", "--time", "120"], Some(SECRET));
    let bearer = format!("Bearer {SECRET}");
    let auth = [("Authorization", bearer.as_str())];
    for (method, path) in
        [("GET", "/"), ("GET", "/state.json"), ("GET", "/image.png"), ("GET", "/run.json"), ("POST", "/stop")]
    {
        let reply = http(run.port, method, path, &[], "");
        assert_eq!(reply.status, 401, "{method} {path} without the secret");
    }
    let wrong =
        http(run.port, "GET", "/state.json", &[("Authorization", "Bearer live-page-test-secret-0123456780")], "");
    assert_eq!(wrong.status, 401);
    assert_eq!(http(run.port, "GET", "/state.json", &auth, "").json()["state"], "running", "the stop was refused");
    let form = [("Content-Type", "application/x-www-form-urlencoded")];
    assert_eq!(http(run.port, "POST", "/login", &form, "secret=not-it").status, 401);
    let login = http(run.port, "POST", "/login", &form, &format!("secret={SECRET}"));
    assert_eq!(login.status, 303);
    let cookie = login.head.lines().find_map(|l| l.strip_prefix("set-cookie: ")).expect("a cookie").to_string();
    let cookie = cookie.split(';').next().unwrap().to_string();
    // The head was lower-cased; the cookie's value is hex, its name lower-case.
    assert_eq!(http(run.port, "GET", "/state.json", &[("Cookie", &cookie)], "").status, 200);
    assert_eq!(http(run.port, "POST", "/stop", &auth, "").status, 202);
    run.wait_for("end", |s| s["state"] == "finished");
    run.finish();
    let _ = std::fs::remove_dir_all(dir);
}

/// A packet of tev's protocol as the fake tev read it.
#[derive(Debug)]
enum TevPacket {
    Create { image: String, width: u32, height: u32, channels: Vec<String> },
    Update { image: String, channels: Vec<String>, width: u32, height: u32, data: Vec<f32> },
}

/// Reads tev packets (u32 length including itself, a type byte, the fields) until the peer closes; panics on any
/// packet that is not well formed.
fn read_tev_packets(mut s: TcpStream) -> Vec<TevPacket> {
    let mut packets = Vec::new();
    loop {
        let mut len = [0u8; 4];
        if s.read_exact(&mut len).is_err() {
            return packets;
        }
        let len = u32::from_le_bytes(len) as usize;
        assert!(len >= 5, "a packet of {len} bytes");
        let mut p = vec![0u8; len - 4];
        s.read_exact(&mut p).expect("a whole packet");
        let mut at = 1;
        let string = |p: &[u8], at: &mut usize| {
            let end = p[*at..].iter().position(|&b| b == 0).expect("a NUL-terminated string") + *at;
            let text = String::from_utf8(p[*at..end].to_vec()).expect("UTF-8");
            *at = end + 1;
            text
        };
        let u32_at = |p: &[u8], at: &mut usize| {
            let v = u32::from_le_bytes(p[*at..*at + 4].try_into().unwrap());
            *at += 4;
            v
        };
        match p[0] {
            4 => {
                assert!(p[at] <= 1, "grab focus is a bool");
                at += 1;
                let image = string(&p, &mut at);
                let (width, height, n) = (u32_at(&p, &mut at), u32_at(&p, &mut at), u32_at(&p, &mut at));
                let channels = (0..n).map(|_| string(&p, &mut at)).collect();
                assert_eq!(at, p.len(), "nothing after the channel names");
                packets.push(TevPacket::Create { image, width, height, channels });
            }
            6 => {
                at += 1;
                let image = string(&p, &mut at);
                let n = u32_at(&p, &mut at) as usize;
                let channels: Vec<String> = (0..n).map(|_| string(&p, &mut at)).collect();
                let (x, y, width, height) =
                    (u32_at(&p, &mut at), u32_at(&p, &mut at), u32_at(&p, &mut at), u32_at(&p, &mut at));
                assert_eq!((x, y), (0, 0));
                let longs: Vec<u64> =
                    (0..2 * n).map(|i| u64::from_le_bytes(p[at + 8 * i..at + 8 * i + 8].try_into().unwrap())).collect();
                at += 16 * n;
                assert_eq!(longs, [0, 1, 2, 3, 3, 3], "interleaved RGB: offsets 0, 1, 2 and stride 3");
                let data: Vec<f32> =
                    p[at..].chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
                assert_eq!(data.len() * 4, p.len() - at);
                assert_eq!(data.len(), (width * height) as usize * n, "one value per pixel and channel");
                packets.push(TevPacket::Update { image, channels, width, height, data });
            }
            other => panic!("an unexpected packet type {other}"),
        }
    }
}

#[test]
fn every_layer_reaches_tev_in_well_formed_packets_and_a_missing_tev_is_only_a_warning() {
    let dir = scratch_dir("live-tev");
    let scene = cornell_at(&dir, 24);
    let tev = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = format!("tev={}", tev.local_addr().unwrap());
    let reader = std::thread::spawn(move || read_tev_packets(tev.accept().unwrap().0));
    let out = dir.join("out");
    let run = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--method", "pbpm", "--phases", "6", "--display", &address])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let packets = reader.join().unwrap();
    let TevPacket::Create { image, width, height, channels } = &packets[0] else { panic!("CreateImage first") };
    assert_eq!((image.as_str(), *width, *height), ("out", 24, 24));
    let layers: Vec<String> = read_exr(&out.join("image.exr")).unwrap().into_iter().map(|l| l.name).collect();
    for layer in &layers {
        let rgb: Vec<String> = ["R", "G", "B"].iter().map(|c| format!("{layer}.{c}")).collect();
        assert!(rgb.iter().all(|c| channels.contains(c)), "{layer} created in {channels:?}");
        let updated = packets.iter().any(|p| {
            matches!(p, TevPacket::Update { image: i, channels: c, width: 24, height: 24, data }
                if i == "out" && *c == rgb && data.iter().all(|v| v.is_finite()))
        });
        assert!(updated, "no update of {layer}");
    }
    let lit = packets.iter().any(|p| {
        matches!(p, TevPacket::Update { channels, data, .. }
        if channels[0] == "total.R" && data.iter().any(|&v| v > 0.0))
    });
    assert!(lit, "the total layer that reached tev has light");

    let nobody = TcpListener::bind("127.0.0.1:0").unwrap();
    let closed = format!("tev={}", nobody.local_addr().unwrap());
    drop(nobody);
    let run = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&scene)
        .arg("--out")
        .arg(dir.join("no-tev"))
        .args(["--quiet", "--method", "pbpm", "--phases", "2", "--display", &closed])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && err.contains("WARN") && err.contains("no tev at"), "{err}");
    assert!(dir.join("no-tev/image.exr").is_file());
    // The warning is a log event: RUST_LOG=error filters it out, and the run's summary stays.
    let quiet = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&scene)
        .arg("--out")
        .arg(dir.join("no-tev-quiet"))
        .args(["--method", "pbpm", "--phases", "2", "--display", &closed])
        .env("RUST_LOG", "error")
        .output()
        .unwrap();
    let (err, out) = (String::from_utf8_lossy(&quiet.stderr), String::from_utf8_lossy(&quiet.stdout));
    assert!(quiet.status.success() && !err.contains("no tev at"), "{err}");
    assert!(out.contains("phases in") && out.contains("wrote"), "the summary: {out}");
    let _ = std::fs::remove_dir_all(dir);
}

/// Pixels of an RGB buffer for which `test` holds.
fn count(rgb: &[u8], test: impl Fn(i32, i32, i32) -> bool) -> usize {
    rgb.chunks_exact(3).filter(|p| test(p[0].into(), p[1].into(), p[2].into())).count()
}

#[test]
fn a_headless_browser_shows_the_image_and_the_error_chart_of_a_running_render() {
    let installed = Command::new(repo_root().join("scripts/chromium")).output().expect("scripts/chromium runs");
    assert!(installed.status.success(), "{}", String::from_utf8_lossy(&installed.stderr));
    let chromium = String::from_utf8_lossy(&installed.stdout).trim().to_string();
    let dir = scratch_dir("live-browser");
    let scene = cornell_at(&dir, 96);
    let run = serve(&scene, &dir.join("out"), "127.0.0.1:0", &["--method", "pbpm", "--time", "120"], None);
    run.wait_for("a few points of δ", |s| {
        s["history"].as_array().is_some_and(|h| h.len() >= 4) && s["delta_unlit"].is_f64()
    });
    let shot = dir.join("page.png");
    let browser = Command::new(&chromium)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        .args(["--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"])
        .arg(format!("--user-data-dir={}", dir.join("profile").display()))
        .args(["--window-size=1100,700", "--virtual-time-budget=3000"])
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("http://127.0.0.1:{}/", run.port))
        .output()
        .unwrap();
    assert!(shot.is_file(), "no screenshot: {}", String::from_utf8_lossy(&browser.stderr));
    http(run.port, "POST", "/stop", &[], "");
    run.finish();
    let (width, height, rgb) = decode_png(&std::fs::read(&shot).unwrap());
    assert_eq!((width, height), (1100, 700));
    // The Cornell box's green wall: the page itself has no green area.
    let green = count(&rgb, |r, g, b| g > r + 40 && g > b + 40 && g > 60);
    assert!(green > 300, "the image is not shown: {green} green pixels");
    // The chart's δ curves, in the chart's blue and orange: more than their legend samples.
    let blue = count(&rgb, |r, g, b| (r - 31).abs() < 12 && (g - 119).abs() < 12 && (b - 180).abs() < 12);
    let orange = count(&rgb, |r, g, b| (r - 255).abs() < 12 && (g - 127).abs() < 12 && (b - 14).abs() < 12);
    assert!(blue > 250 && orange > 250, "the chart is not drawn: {blue} blue and {orange} orange pixels");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_bench_page_lists_the_runs_and_serves_each_chart_once_drawn() {
    let out = scratch_dir("live-bench");
    let mut child = Command::new(binary("coordinator"))
        .args(["bench", "--time", "1", "--scenes", "cornell", "--methods", "pbpm,sync", "--threads", "1", "--serve"])
        .arg("--out")
        .arg(&out)
        .current_dir(repo_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let port: u16 = first
        .strip_prefix("live page: http://127.0.0.1:")
        .and_then(|rest| rest.split('/').next()?.parse().ok())
        .unwrap_or_else(|| panic!("the first line gives the page's URL: {first}"));
    let drain = std::thread::spawn(move || lines.map_while(Result::ok).count());
    assert!(http(port, "GET", "/", &[], "").text().contains("photonfarm: bench"));
    let deadline = Instant::now() + Duration::from_secs(120);
    let mut seen_running = false;
    let state = loop {
        let s = http(port, "GET", "/state.json", &[], "").json();
        let runs = s["runs"].as_array().unwrap().clone();
        assert_eq!(runs.len(), 2, "{s}");
        assert_eq!(runs[0]["label"], "cornell pbpm 1 threads, run 1");
        seen_running |= runs.iter().any(|r| r["state"] == "running");
        if s["finished"] == true {
            break s;
        }
        assert!(s["failed"].is_null() && Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(seen_running, "a run was shown running");
    assert!(state["runs"].as_array().unwrap().iter().all(|r| r["state"] == "done" && r["result"].is_string()));
    let charts: Vec<&str> = state["charts"].as_array().unwrap().iter().map(|c| c.as_str().unwrap()).collect();
    assert!(charts.contains(&"error-vs-time-cornell.png"), "{charts:?}");
    for c in &charts {
        let reply = http(port, "GET", &format!("/charts/{c}"), &[], "");
        assert_eq!((reply.status, decode_png(&reply.body).0), (200, 1024), "{c}");
    }
    assert_eq!(http(port, "GET", "/charts/results.csv", &[], "").status, 404, "only the charts are served");
    assert!(child.wait().unwrap().success());
    drain.join().unwrap();
    let _ = std::fs::remove_dir_all(out);
}
