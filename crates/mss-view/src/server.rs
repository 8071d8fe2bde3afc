//! The HTTP and WebSocket server of the viewer (axum on tokio).
//!
//! Routes: `/` (the page), `/viewer.js`, `/viewer.css` and `/ws` (the
//! WebSocket). Every request, the upgrade included, must carry
//! `?token=TOKEN`; without it, or with a wrong one, the answer is 403
//! before any routing, so nothing about the server is learnt without the
//! token. No route maps a request path to a file: the assets are strings
//! compiled into the binary.
//!
//! Each WebSocket sends the latest scene and then, whenever the source
//! publishes, the latest frame: a page that reads slowly skips frames
//! (the watch channel keeps only the newest), and the source never waits
//! for a page.

use std::sync::Arc;
use std::sync::mpsc::{SyncSender, TrySendError};

use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

use crate::Published;
use crate::protocol::{ClientMessage, MAX_CLIENT_MESSAGE_BYTES};

const INDEX_HTML: &str = include_str!("../assets/index.html");
const VIEWER_JS: &str = include_str!("../assets/viewer.js");
const VIEWER_CSS: &str = include_str!("../assets/viewer.css");

/// What every handler shares.
#[derive(Clone)]
pub(crate) struct ServerState {
    token: Arc<str>,
    published: tokio::sync::watch::Receiver<Published>,
    commands: SyncSender<ClientMessage>,
}

impl ServerState {
    pub(crate) fn new(
        token: String,
        published: tokio::sync::watch::Receiver<Published>,
        commands: SyncSender<ClientMessage>,
    ) -> Self {
        Self {
            token: token.into(),
            published,
            commands,
        }
    }
}

/// Compares in time independent of where the strings differ.
fn same_token(given: &str, expected: &str) -> bool {
    let (a, b) = (given.as_bytes(), expected.as_bytes());
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn token_of(query: Option<&str>) -> Option<&str> {
    query?.split('&').find_map(|kv| kv.strip_prefix("token="))
}

async fn require_token(State(state): State<ServerState>, request: Request, next: Next) -> Response {
    let ok = token_of(request.uri().query()).is_some_and(|t| same_token(t, &state.token));
    if !ok {
        log::warn!(
            "viewer: refused {} {} (no valid token)",
            request.method(),
            request.uri().path()
        );
        return (
            StatusCode::FORBIDDEN,
            "403 forbidden: this viewer needs the token of the URL that `mss view` printed\n",
        )
            .into_response();
    }
    let mut response = next.run(request).await;
    let headers = response.headers_mut();
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    headers.insert(
        "x-content-type-options",
        HeaderValue::from_static("nosniff"),
    );
    response
}

fn asset(body: &'static str, content_type: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type)], body).into_response()
}

async fn index(State(state): State<ServerState>) -> Response {
    // The page asks for its assets with the same token.
    let page = INDEX_HTML.replace("__TOKEN__", &state.token);
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:; style-src 'self'; script-src 'self'",
            ),
        ],
        page,
    )
        .into_response()
}

async fn viewer_js() -> Response {
    asset(VIEWER_JS, "text/javascript; charset=utf-8")
}

async fn viewer_css() -> Response {
    asset(VIEWER_CSS, "text/css; charset=utf-8")
}

async fn not_found() -> Response {
    (StatusCode::NOT_FOUND, "404 not found\n").into_response()
}

async fn websocket(State(state): State<ServerState>, upgrade: WebSocketUpgrade) -> Response {
    upgrade
        .max_message_size(MAX_CLIENT_MESSAGE_BYTES)
        .max_frame_size(MAX_CLIENT_MESSAGE_BYTES)
        .on_upgrade(move |socket| connection(socket, state))
}

/// Sends the scene (and the frame after it) if it is new to this page.
async fn send_latest(
    socket: &mut WebSocket,
    published: &Published,
    sent_scene: &mut Option<u64>,
    sent_frame: &mut Option<(u64, u64)>,
) -> Result<(), axum::Error> {
    let Some(scene) = &published.scene else {
        return Ok(());
    };
    if *sent_scene != Some(scene.info.generation) {
        socket
            .send(Message::Text(scene.json.clone().into()))
            .await?;
        socket
            .send(Message::Binary(scene.topology.clone().into()))
            .await?;
        *sent_scene = Some(scene.info.generation);
        *sent_frame = None;
    }
    if let Some(frame) = &published.frame {
        let key = (frame.status.generation, frame.status.seq);
        if frame.status.generation == scene.info.generation && *sent_frame != Some(key) {
            socket
                .send(Message::Text(frame.json.clone().into()))
                .await?;
            socket
                .send(Message::Binary(frame.binary.clone().into()))
                .await?;
            *sent_frame = Some(key);
        }
    }
    Ok(())
}

fn forward(state: &ServerState, text: &str) {
    match ClientMessage::parse(text) {
        Ok(message) => match state.commands.try_send(message) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                log::warn!("viewer: the source is busy; a message was dropped")
            }
            Err(TrySendError::Disconnected(_)) => {}
        },
        Err(e) => log::warn!("viewer: ignored a message from the page: {e}"),
    }
}

async fn connection(mut socket: WebSocket, state: ServerState) {
    let mut published = state.published.clone();
    let mut sent_scene = None;
    let mut sent_frame = None;
    log::info!("viewer: a page connected");
    loop {
        let latest = published.borrow_and_update().clone();
        if send_latest(&mut socket, &latest, &mut sent_scene, &mut sent_frame)
            .await
            .is_err()
        {
            break;
        }
        tokio::select! {
            changed = published.changed() => {
                if changed.is_err() {
                    break;
                }
            }
            incoming = socket.recv() => {
                match incoming {
                    Some(Ok(Message::Text(text))) => forward(&state, text.as_str()),
                    Some(Ok(Message::Binary(_))) => log::warn!("viewer: ignored a binary message from the page"),
                    Some(Ok(Message::Close(_))) | None => break,
                    Some(Ok(_)) => {}
                    Some(Err(e)) => {
                        log::warn!("viewer: page connection failed: {e}");
                        break;
                    }
                }
            }
        }
    }
    log::info!("viewer: a page disconnected");
}

/// Serves until `shutdown` fires.
pub(crate) async fn serve(
    listener: tokio::net::TcpListener,
    state: ServerState,
    shutdown: tokio::sync::oneshot::Receiver<()>,
) {
    let app = Router::new()
        .route("/", get(index))
        .route("/index.html", get(index))
        .route("/viewer.js", get(viewer_js))
        .route("/viewer.css", get(viewer_css))
        .route("/ws", get(websocket))
        .fallback(not_found)
        .layer(middleware::from_fn_with_state(state.clone(), require_token))
        .with_state(state);
    let result = axum::serve(listener, app)
        .with_graceful_shutdown(async {
            let _ = shutdown.await;
        })
        .await;
    if let Err(e) = result {
        log::error!("viewer: server stopped: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_compare_whole() {
        assert!(same_token("abc", "abc"));
        assert!(!same_token("abd", "abc"));
        assert!(!same_token("ab", "abc"));
        assert!(!same_token("", "abc"));
        assert_eq!(token_of(Some("a=1&token=xyz")), Some("xyz"));
        assert_eq!(token_of(Some("tokens=xyz")), None);
        assert_eq!(token_of(None), None);
    }
}
