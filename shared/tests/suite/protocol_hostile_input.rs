//! The protocol under hostile or mistaken peers: wrong secrets, wrong versions, forged lengths and random bytes
//! are refused with an error, never a panic or an unbounded allocation.

use photonfarm::protocol::auth::handshake;
use photonfarm::protocol::frame::read_frame;
use photonfarm::protocol::message::{decode, encode};
use photonfarm::protocol::{Connection, Message, ProtocolError, Role, Secret, PROTOCOL_VERSION};
use proptest::prelude::*;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap()
}

fn secret(s: &str) -> Secret {
    Secret::from_bytes(s.as_bytes(), "test").unwrap()
}

/// Runs a coordinator-side and a worker-side handshake against each other over loopback TCP.
async fn pair(coordinator: Secret, worker: Secret) -> (Result<(), ProtocolError>, Result<(), ProtocolError>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = tokio::spawn(async move {
        let (s, _) = listener.accept().await.unwrap();
        let mut c = Connection::new(s).unwrap();
        handshake(&mut c, Role::Coordinator, "c", &coordinator).await.map(|_| ())
    });
    let mut c = Connection::new(TcpStream::connect(addr).await.unwrap()).unwrap();
    let w = handshake(&mut c, Role::Worker, "w", &worker).await.map(|_| ());
    (server.await.unwrap(), w)
}

#[test]
fn peers_with_the_same_secret_authenticate_each_other() {
    let (c, w) =
        runtime().block_on(pair(secret("a shared secret of some length"), secret("a shared secret of some length")));
    assert!(c.is_ok() && w.is_ok(), "{c:?} {w:?}");
}

#[test]
fn a_wrong_secret_is_refused_on_both_sides() {
    let (c, w) = runtime().block_on(pair(secret("the coordinator's secret 1"), secret("the worker's other secret")));
    assert!(matches!(c, Err(ProtocolError::Authentication)), "{c:?}");
    assert!(matches!(w, Err(ProtocolError::Authentication)), "{w:?}");
}

#[test]
fn an_insecure_peer_cannot_pass_for_one_that_knows_the_secret() {
    let (c, _) = runtime().block_on(pair(secret("the coordinator's secret 1"), Secret::insecure()));
    assert!(matches!(c, Err(ProtocolError::Authentication)), "{c:?}");
}

/// A coordinator that runs one handshake on a loopback port; returns the port and the handshake's outcome.
async fn coordinator_handshake() -> (std::net::SocketAddr, tokio::task::JoinHandle<Result<(), ProtocolError>>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = tokio::spawn(async move {
        let (s, _) = listener.accept().await.unwrap();
        let mut c = Connection::new(s).unwrap();
        handshake(&mut c, Role::Coordinator, "c", &secret("a shared secret of some length")).await.map(|_| ())
    });
    (addr, server)
}

#[test]
fn another_protocol_version_is_refused_with_a_reason() {
    runtime().block_on(async {
        let (addr, server) = coordinator_handshake().await;
        let mut c = Connection::new(TcpStream::connect(addr).await.unwrap()).unwrap();
        c.write(&Message::Hello {
            version: PROTOCOL_VERSION + 1,
            role: Role::Worker,
            nonce: [0; 32],
            name: "old".into(),
        })
        .await
        .unwrap();
        let err = server.await.unwrap().unwrap_err();
        assert!(matches!(err, ProtocolError::Version { theirs, .. } if theirs == PROTOCOL_VERSION + 1), "{err}");
        // The peer is told why before the link closes.
        let mut saw_refusal = false;
        while let Ok(m) = c.read().await {
            if let Message::Refused { reason } = m {
                assert!(reason.contains("version"), "{reason}");
                saw_refusal = true;
            }
        }
        assert!(saw_refusal);
    });
}

#[test]
fn garbage_instead_of_a_hello_ends_the_handshake_with_an_error() {
    runtime().block_on(async {
        let (addr, server) = coordinator_handshake().await;
        let mut s = TcpStream::connect(addr).await.unwrap();
        // A length prefix of 3.9 GB, then close.
        s.write_all(&[0xe8, 0xd4, 0xa5, 0x10]).await.unwrap();
        drop(s);
        let err = server.await.unwrap().unwrap_err();
        assert!(matches!(err, ProtocolError::FrameTooLarge { .. }), "{err}");
    });
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic_the_frame_reader_or_the_decoder(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let rt = runtime();
        let mut r = &bytes[..];
        while let Ok(Some(body)) = rt.block_on(read_frame(&mut r, 1 << 16)) {
            let _ = decode(&body);
        }
        let _ = decode(&bytes);
    }

    #[test]
    fn every_truncation_of_a_valid_message_is_refused(cut in 0usize..64) {
        let body = encode(&Message::Hello { version: 1, role: Role::Worker, nonce: [9; 32], name: "worker".into() }).unwrap();
        let cut = cut.min(body.len() - 1);
        prop_assert!(decode(&body[..cut]).is_err());
    }
}
