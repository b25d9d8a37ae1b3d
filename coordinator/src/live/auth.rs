//! Who may use a live page. On loopback, whoever can reach the port is on this machine and the page is open;
//! on any other address the page asks for the job's secret (`--secret-file` or `$PHOTONFARM_SECRET`, the one
//! remote workers use), as a bearer token or as the cookie its login form sets. Nobody can watch or stop a run
//! they could not have started.

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{Html, IntoResponse, Response};
use axum::Form;
use photonfarm::protocol::Secret;
use std::net::SocketAddr;
use std::sync::Arc;

/// The form a browser without the secret is shown (with status 401).
const LOGIN_PAGE: &str = r#"<!doctype html><meta charset="utf-8"><title>photonfarm: secret needed</title>
<body style="font-family:sans-serif;margin:3em">
<p>This page needs the job's secret (the content of <code>--secret-file</code> or <code>$PHOTONFARM_SECRET</code>).</p>
<form method="post" action="/login"><input type="password" name="secret" autofocus size="40">
<button>Open</button></form></body>"#;

/// Who may use a page.
#[derive(Clone, Debug)]
pub enum Access {
    /// Bound to loopback: anyone who can connect.
    Open,
    /// Requests must present the secret; `cookie` is the name of the cookie that carries it.
    Secret { secret: Arc<Secret>, cookie: String },
}

impl Access {
    /// The access of a page bound to `addr`: open on loopback; elsewhere the secret, and an error without one.
    pub fn for_bind(addr: SocketAddr, secret: Option<Secret>) -> anyhow::Result<Access> {
        if addr.ip().is_loopback() {
            return Ok(Access::Open);
        }
        match secret {
            Some(s) if !s.is_insecure() => Ok(Access::Secret {
                secret: Arc::new(s),
                // Cookies do not tell ports apart: one name per port keeps two pages on a host from mixing.
                cookie: format!("photonfarm_secret_{}", addr.port()),
            }),
            _ => anyhow::bail!(
                "--serve {addr} is not a loopback address: the page would let anyone who reaches it watch and stop \
                 the run, so it needs the job's secret (--secret-file FILE or $PHOTONFARM_SECRET; --insecure does \
                 not apply to the page); or serve on 127.0.0.1 and forward the port (ssh -L)"
            ),
        }
    }

    fn admits(&self, headers: &HeaderMap) -> bool {
        match self {
            Access::Open => true,
            Access::Secret { secret, cookie } => {
                let bearer = headers
                    .get(header::AUTHORIZATION)
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.strip_prefix("Bearer "))
                    .is_some_and(|token| secret.matches(token.as_bytes()));
                bearer
                    || cookie_value(headers, cookie).and_then(|hex| from_hex(&hex)).is_some_and(|s| secret.matches(&s))
            }
        }
    }
}

/// Middleware: passes admitted requests on and answers the others 401 with the login form.
pub async fn require(State(access): State<Access>, request: Request, next: Next) -> Response {
    if access.admits(request.headers()) {
        next.run(request).await
    } else {
        (StatusCode::UNAUTHORIZED, [(header::WWW_AUTHENTICATE, "Bearer")], Html(LOGIN_PAGE)).into_response()
    }
}

/// The login form's fields.
#[derive(serde::Deserialize)]
pub struct Login {
    secret: String,
}

/// `POST /login`: with the secret, sets the page's cookie and goes to the page; without, 401 and the form again.
pub async fn login(State(access): State<Access>, Form(login): Form<Login>) -> Response {
    let Access::Secret { secret, cookie } = &access else {
        return (StatusCode::SEE_OTHER, [(header::LOCATION, "/")]).into_response();
    };
    if !secret.matches(login.secret.as_bytes()) {
        return (StatusCode::UNAUTHORIZED, Html(LOGIN_PAGE)).into_response();
    }
    let value = format!("{cookie}={}; HttpOnly; SameSite=Strict; Path=/", to_hex(login.secret.trim().as_bytes()));
    match HeaderValue::from_str(&value) {
        Ok(v) => (StatusCode::SEE_OTHER, [(header::LOCATION, HeaderValue::from_static("/")), (header::SET_COOKIE, v)])
            .into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "cannot set the cookie").into_response(),
    }
}

fn cookie_value(headers: &HeaderMap, name: &str) -> Option<String> {
    headers.get_all(header::COOKIE).iter().filter_map(|v| v.to_str().ok()).flat_map(|v| v.split(';')).find_map(|pair| {
        let (k, v) = pair.trim().split_once('=')?;
        (k == name).then(|| v.to_string())
    })
}

/// The secret travels hex-encoded in its cookie: a secret file may hold bytes a cookie cannot.
fn to_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn from_hex(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len()).step_by(2).map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_loopback_page_needs_a_secret_and_admits_only_its_bearer_or_cookie() {
        let any: SocketAddr = "0.0.0.0:8080".parse().unwrap();
        let e = Access::for_bind(any, None).unwrap_err().to_string();
        assert!(e.contains("secret") && e.contains("0.0.0.0:8080"), "{e}");
        assert!(Access::for_bind(any, Some(Secret::insecure())).is_err());
        assert!(matches!(Access::for_bind("127.0.0.1:0".parse().unwrap(), None).unwrap(), Access::Open));

        let secret = Secret::from_bytes(b"a secret of 24 bytes....", "test").unwrap();
        let access = Access::for_bind(any, Some(secret)).unwrap();
        let with = |name: header::HeaderName, value: String| {
            let mut h = HeaderMap::new();
            h.insert(name, HeaderValue::from_str(&value).unwrap());
            access.admits(&h)
        };
        assert!(!access.admits(&HeaderMap::new()));
        assert!(with(header::AUTHORIZATION, "Bearer a secret of 24 bytes....".into()));
        assert!(!with(header::AUTHORIZATION, "Bearer a secret of 24 bytes...!".into()));
        let cookie = format!("other=1; photonfarm_secret_8080={}", to_hex(b"a secret of 24 bytes...."));
        assert!(with(header::COOKIE, cookie));
        assert!(!with(header::COOKIE, format!("photonfarm_secret_8081={}", to_hex(b"a secret of 24 bytes...."))));
        assert!(!with(header::COOKIE, "photonfarm_secret_8080=zz".into()));
    }
}
