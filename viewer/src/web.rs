//! The view's serving side: the page's files (embedded in the binary), a
//! small JSON API, and the WebSocket each open page listens on.
//!
//! A page's connection sends everything the page needs once (the maps, the
//! shown map's geometry and tiles, the robots with their paths), then every
//! 50 ms what changed since: each changed tile once, however often it
//! changed, and each robot that moved. A page that falls behind is sent
//! everything again.

use std::collections::{BTreeSet, HashSet};
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use deog_grid::TileKey;
use serde::Deserialize;
use serde_json::Value;
use tokio::sync::broadcast::error::RecvError;

use crate::feeds::{Shared, Update};
use crate::protocol;
use crate::state::Change;

/// How often a page is sent what changed.
const PUSH_PERIOD: Duration = Duration::from_millis(50);

const INDEX_HTML: &str = include_str!("../web/index.html");
const APP_JS: &str = include_str!("../web/app.js");
const STYLE_CSS: &str = include_str!("../web/style.css");

/// The routes: `/` (the page), `/app.js`, `/style.css`, `/api/maps`,
/// `/api/robots` and `/ws` (`?map=NAME` to pick the map shown).
pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { file("text/html; charset=utf-8", INDEX_HTML) }),
        )
        .route(
            "/app.js",
            get(|| async { file("text/javascript; charset=utf-8", APP_JS) }),
        )
        .route(
            "/style.css",
            get(|| async { file("text/css; charset=utf-8", STYLE_CSS) }),
        )
        .route("/api/maps", get(api_maps))
        .route("/api/robots", get(api_robots))
        .route("/ws", get(websocket))
        .with_state(shared)
}

fn file(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn api_maps(State(shared): State<Arc<Shared>>) -> Response {
    json_response(&protocol::maps(&shared.maps()))
}

async fn api_robots(State(shared): State<Arc<Shared>>) -> Response {
    let state = shared.state();
    let value = protocol::robots(state.robots().iter().map(|(n, t)| (n.as_str(), t)), false);
    drop(state);
    json_response(&value)
}

fn json_response(value: &Value) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        value.to_string(),
    )
        .into_response()
}

#[derive(Debug, Deserialize)]
struct ShowQuery {
    map: Option<String>,
}

async fn websocket(
    upgrade: WebSocketUpgrade,
    State(shared): State<Arc<Shared>>,
    Query(query): Query<ShowQuery>,
) -> Response {
    upgrade.on_upgrade(move |socket| async move {
        let mut page = PageConnection::new(shared, query.map);
        if let Err(error) = page.run(socket).await {
            tracing::debug!(%error, "a page's connection ended");
        }
    })
}

/// A message from the page.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
enum PageRequest {
    /// Show another map.
    Show { map: String },
}

/// One open page: what it shows and what it has not been sent yet.
struct PageConnection {
    shared: Arc<Shared>,
    map: Option<String>,
    geometry_sent: bool,
    everything: bool,
    tiles: HashSet<TileKey>,
    robots: BTreeSet<String>,
    kidnaps: Vec<String>,
    particles: BTreeSet<String>,
    maps_changed: bool,
    cleared: bool,
}

impl PageConnection {
    fn new(shared: Arc<Shared>, map: Option<String>) -> Self {
        Self {
            shared,
            map,
            geometry_sent: false,
            everything: true,
            tiles: HashSet::new(),
            robots: BTreeSet::new(),
            kidnaps: Vec::new(),
            particles: BTreeSet::new(),
            maps_changed: false,
            cleared: false,
        }
    }

    async fn run(&mut self, mut socket: WebSocket) -> Result<(), axum::Error> {
        let mut updates = self.shared.subscribe();
        if self.map.is_none() {
            self.map = self.shared.map_to_show();
        }
        if let Some(map) = &self.map {
            self.shared.follow_map(map);
        }
        let world = self
            .shared
            .world
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let hello = protocol::hello(&self.shared.maps(), self.map.as_deref(), world.as_deref());
        socket.send(text(&hello)).await?;
        let mut tick = tokio::time::interval(PUSH_PERIOD);
        loop {
            tokio::select! {
                () = self.shared.shutdown.cancelled() => {
                    let _ = socket.send(Message::Close(None)).await;
                    return Ok(());
                }
                _ = tick.tick() => self.push(&mut socket).await?,
                update = updates.recv() => match update {
                    Ok(update) => self.note(update),
                    Err(RecvError::Lagged(_)) => {
                        self.everything = true;
                        self.geometry_sent = false;
                    }
                    Err(RecvError::Closed) => return Ok(()),
                },
                message = socket.recv() => match message {
                    None | Some(Ok(Message::Close(_))) => return Ok(()),
                    Some(Ok(Message::Text(body))) => self.take_request(body.as_str()),
                    Some(Ok(_)) => {}
                    Some(Err(error)) => return Err(error),
                },
            }
        }
    }

    fn take_request(&mut self, body: &str) {
        match serde_json::from_str::<PageRequest>(body) {
            Ok(PageRequest::Show { map }) => {
                self.shared.follow_map(&map);
                self.map = Some(map);
                self.geometry_sent = false;
                self.tiles.clear();
            }
            Err(error) => tracing::debug!(%error, "a page sent what is not a request"),
        }
    }

    fn note(&mut self, update: Update) {
        match update {
            Update::Maps => self.maps_changed = true,
            Update::State(Change::Tile { map, key }) => {
                if self.map.as_deref() == Some(map.as_str()) {
                    self.tiles.insert(key);
                }
            }
            Update::State(Change::Cleared { map }) => {
                if self.map.as_deref() == Some(map.as_str()) {
                    self.cleared = true;
                    self.tiles.clear();
                }
            }
            Update::State(Change::Robot(robot)) => {
                self.robots.insert(robot);
            }
            Update::State(Change::Kidnap(robot)) => self.kidnaps.push(robot),
            Update::State(Change::Particles(robot)) => {
                self.particles.insert(robot);
            }
        }
    }

    /// Sends what changed since the last push. The messages are made under
    /// the state's lock and sent after it is released.
    async fn push(&mut self, socket: &mut WebSocket) -> Result<(), axum::Error> {
        let mut out = Vec::new();
        if self.maps_changed {
            self.maps_changed = false;
            out.push(text(&protocol::maps(&self.shared.maps())));
        }
        {
            let state = self.shared.state();
            if let Some(map) = &self.map {
                if self.cleared {
                    self.cleared = false;
                    out.push(text(&protocol::cleared(map)));
                }
                if let Some(layer) = state.map(map) {
                    let side = layer.tile_size.cells();
                    if !self.geometry_sent {
                        self.geometry_sent = true;
                        self.tiles.clear();
                        out.push(text(&protocol::map_geometry(map, layer)));
                        for (key, (_, shades)) in &layer.tiles {
                            out.push(binary(protocol::tile_message(*key, side, shades)));
                        }
                    } else {
                        for key in self.tiles.drain() {
                            if let Some((_, shades)) = layer.tiles.get(&key) {
                                out.push(binary(protocol::tile_message(key, side, shades)));
                            }
                        }
                    }
                }
            }
            if self.everything {
                self.everything = false;
                self.robots.clear();
                self.kidnaps.clear();
                let all = state.robots().iter().map(|(n, t)| (n.as_str(), t));
                out.push(text(&protocol::robots(all, true)));
                self.particles = state.robots().keys().cloned().collect();
            } else if !self.robots.is_empty() {
                let robots = std::mem::take(&mut self.robots);
                let changed = robots
                    .iter()
                    .filter_map(|name| state.robots().get(name).map(|t| (name.as_str(), t)));
                out.push(text(&protocol::robots(changed, false)));
            }
            for robot in self.kidnaps.drain(..) {
                if let Some(message) = state
                    .robots()
                    .get(&robot)
                    .and_then(|t| protocol::kidnap(&robot, t))
                {
                    out.push(text(&message));
                }
            }
            for robot in std::mem::take(&mut self.particles) {
                if let Some(message) = state
                    .robots()
                    .get(&robot)
                    .and_then(|t| protocol::particles(&robot, t))
                {
                    out.push(text(&message));
                }
            }
        }
        for message in out {
            socket.send(message).await?;
        }
        Ok(())
    }
}

fn text(value: &Value) -> Message {
    Message::Text(value.to_string().into())
}

fn binary(bytes: Vec<u8>) -> Message {
    Message::Binary(bytes.into())
}
