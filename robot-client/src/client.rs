//! [`MapClient`]: typed calls to the map server.

use crate::connect::{ClientConfig, RawMapClient, connect, with_retry};
use crate::convert::{cell_box_from_wire, cell_box_to_wire, decode_tile, tile_key_to_wire};
use crate::error::ClientError;
use crate::tile_cache::TileCache;
use crate::updates::{UpdateSender, UpdateSenderConfig};
use deog_grid::{CellBox, CellIndex, ClampLimits, Resolution, Tile, TileKey, TileMap, TileSize};
use deog_proto::rig::{frame_rig_name, rig_from_wire, rig_to_wire};
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use deog_rig::Rig;
use tokio_stream::StreamExt;

/// Tiles read per request by [`MapClient::download_with_progress`], about.
pub const DOWNLOAD_BAND_TILES: u64 = 256;

/// A connection to the map server; cheap to clone.
#[derive(Debug, Clone)]
pub struct MapClient {
    raw: RawMapClient,
    channel: tonic::transport::Channel,
    config: ClientConfig,
}

impl MapClient {
    /// Connects, retrying with backoff while the server is not up yet.
    pub async fn connect(config: ClientConfig) -> Result<Self, ClientError> {
        let (channel, interceptor) = connect(&config).await?;
        let raw = MapServiceClient::with_interceptor(channel.clone(), interceptor)
            .max_decoding_message_size(usize::MAX)
            .max_encoding_message_size(usize::MAX);
        Ok(Self {
            raw,
            channel,
            config,
        })
    }

    /// The connection itself, for the services beside the map service
    /// (health), which take no token.
    pub fn channel(&self) -> tonic::transport::Channel {
        self.channel.clone()
    }

    /// The generated client, for the calls no process makes and this type
    /// therefore does not wrap (tests clear maps with it).
    pub fn raw(&self) -> RawMapClient {
        self.raw.clone()
    }

    /// The configuration this client was made with.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// One unary call under the retry policy: after a transient failure
    /// `call` is made again, with a copy of `request`.
    async fn unary<Request, Reply, Call, Fut>(
        &self,
        request: Request,
        call: Call,
    ) -> Result<Reply, ClientError>
    where
        Request: Clone,
        Call: Fn(RawMapClient, Request) -> Fut,
        Fut: std::future::Future<Output = Result<tonic::Response<Reply>, tonic::Status>>,
    {
        let reply = with_retry(&self.config.retry, || {
            call(self.raw.clone(), request.clone())
        })
        .await?;
        Ok(reply.into_inner())
    }

    /// Creates a map, or returns the existing one of that name.
    pub async fn ensure_map(
        &self,
        request: pb::CreateMapRequest,
    ) -> Result<pb::MapInfo, ClientError> {
        let created = self
            .unary(request.clone(), |mut raw, request| async move {
                raw.create_map(request).await
            })
            .await;
        match created {
            Ok(info) => Ok(info),
            Err(ClientError::Status(s)) if s.code() == tonic::Code::AlreadyExists => {
                self.map_info(&request.name).await
            }
            Err(e) => Err(e),
        }
    }

    /// A whole map: its settings and every stored tile, as a [`TileMap`]
    /// with the map's resolution, tile size and clamp limits. Each tile
    /// comes whole, so this works while the map is still being built.
    pub async fn download(&self, name: &str) -> Result<(pb::MapInfo, TileMap), ClientError> {
        let info = self.map_info(name).await?;
        let resolution = Resolution::new(info.resolution_m)?;
        let tile_size = TileSize::new(info.tile_size)?;
        let limits = ClampLimits::from_probabilities(
            info.clamp_min_probability,
            info.clamp_max_probability,
        )?;
        let mut map = TileMap::new(resolution, tile_size, limits);
        // No bounds: nothing observed yet, so no tile to fetch.
        let Some(region) = info.bounds_cells else {
            return Ok((info, map));
        };
        let region = cell_box_from_wire("bounds_cells", region)?;
        let mut cache = TileCache::new(name, tile_size);
        cache.refresh(self, region).await?;
        for (key, _, tile) in cache.into_tiles() {
            map.insert(key, tile)?;
        }
        Ok((info, map))
    }

    /// As [`MapClient::download`], read in bands of tile rows of about
    /// [`DOWNLOAD_BAND_TILES`] tiles each, telling `progress` after each band
    /// the tiles read so far and the tiles the map held when the download
    /// began. Each tile is a copy as of the moment its band was read.
    pub async fn download_with_progress(
        &self,
        name: &str,
        progress: &mut (dyn FnMut(u64, u64) + Send),
    ) -> Result<(pb::MapInfo, TileMap), ClientError> {
        let info = self.map_info(name).await?;
        let resolution = Resolution::new(info.resolution_m)?;
        let tile_size = TileSize::new(info.tile_size)?;
        let limits = ClampLimits::from_probabilities(
            info.clamp_min_probability,
            info.clamp_max_probability,
        )?;
        let mut map = TileMap::new(resolution, tile_size, limits);
        let Some(region) = info.bounds_cells else {
            progress(0, 0);
            return Ok((info, map));
        };
        let region = cell_box_from_wire("bounds_cells", region)?;
        let (min, max) = tile_size.tiles_covering(&region);
        let columns = (i64::from(max.x) - i64::from(min.x) + 1).max(1) as u64;
        let rows_per_band = (DOWNLOAD_BAND_TILES / columns).max(1) as i64;
        let cells = i64::from(tile_size.cells());
        let mut read = 0u64;
        let mut row = i64::from(min.y);
        while row <= i64::from(max.y) {
            let last_row = (row + rows_per_band - 1).min(i64::from(max.y));
            // Tile rows times the tile's cells stay within the region's
            // own i32 range once clamped to it.
            let low = (row * cells).max(i64::from(region.min.y));
            let high = ((last_row + 1) * cells - 1).min(i64::from(region.max.y));
            let band = CellBox {
                min: CellIndex::new(region.min.x, low as i32),
                max: CellIndex::new(region.max.x, high as i32),
            };
            for (key, _, tile) in self.tiles_in_region(name, tile_size, band).await? {
                map.insert(key, tile)?;
                read += 1;
            }
            progress(read, info.tile_count);
            row = last_row + 1;
        }
        Ok((info, map))
    }

    /// A map's settings and counts.
    pub async fn map_info(&self, name: &str) -> Result<pb::MapInfo, ClientError> {
        let request = pb::MapRef {
            name: name.to_string(),
        };
        self.unary(request, |mut raw, request| async move {
            raw.get_map_info(request).await
        })
        .await
    }

    /// Every map the server holds.
    pub async fn maps(&self) -> Result<Vec<pb::MapInfo>, ClientError> {
        Ok(self
            .unary((), |mut raw, ()| async move {
                raw.list_maps(pb::ListMapsRequest {}).await
            })
            .await?
            .maps)
    }

    /// The highest batch sequence the server applied for `client_id`.
    pub async fn update_cursor(&self, map: &str, client_id: &str) -> Result<u64, ClientError> {
        let request = pb::UpdateCursorRequest {
            map: map.to_string(),
            client_id: client_id.to_string(),
        };
        Ok(self
            .unary(request, |mut raw, request| async move {
                raw.get_update_cursor(request).await
            })
            .await?
            .last_sequence)
    }

    /// Every client that applied batches to map `map`, with its highest
    /// applied sequence, by client id: who writes to the map. One attempt,
    /// no retry: callers that poll it ask again anyway.
    pub async fn update_cursors(
        &self,
        map: &str,
    ) -> Result<Vec<pb::ClientUpdateCursor>, ClientError> {
        let request = pb::MapRef {
            name: map.to_string(),
        };
        Ok(self
            .raw
            .clone()
            .list_update_cursors(request)
            .await?
            .into_inner()
            .cursors)
    }

    /// Every stored tile that the query selects.
    pub async fn tiles(&self, query: pb::TileQuery) -> Result<Vec<pb::Tile>, ClientError> {
        let mut stream = self.raw.clone().get_tiles(query).await?.into_inner();
        let mut out = Vec::new();
        while let Some(tile) = stream.next().await {
            out.push(tile?);
        }
        Ok(out)
    }

    /// The tiles `keys` of `map` that the server has, decoded, with their
    /// versions; a key left out has no tile (every cell unknown).
    pub async fn tiles_by_key(
        &self,
        map: &str,
        tile_size: TileSize,
        keys: &[TileKey],
    ) -> Result<Vec<(TileKey, u64, Tile)>, ClientError> {
        let wire = self
            .tiles(pb::TileQuery {
                map: map.to_string(),
                selection: Some(pb::tile_query::Selection::Keys(pb::TileKeys {
                    keys: keys.iter().copied().map(tile_key_to_wire).collect(),
                })),
                newer_than_version: 0,
            })
            .await?;
        wire.iter().map(|t| decode_tile(t, tile_size)).collect()
    }

    /// Every tile of `map` within `region` that the server has, decoded,
    /// with its version.
    pub async fn tiles_in_region(
        &self,
        map: &str,
        tile_size: TileSize,
        region: CellBox,
    ) -> Result<Vec<(TileKey, u64, Tile)>, ClientError> {
        let wire = self
            .tiles(pb::TileQuery {
                map: map.to_string(),
                selection: Some(pb::tile_query::Selection::Region(cell_box_to_wire(region))),
                newer_than_version: 0,
            })
            .await?;
        wire.iter().map(|t| decode_tile(t, tile_size)).collect()
    }

    /// Streams the tile events of `region` on `map` as they happen: changes
    /// (with their cells when `include_cells`), resyncs after the stream
    /// fell behind, and clears. Open it before reading the tiles, so no
    /// change in between is missed.
    pub async fn watch_tiles(
        &self,
        map: &str,
        region: CellBox,
        include_cells: bool,
    ) -> Result<tonic::Streaming<pb::TileEvent>, ClientError> {
        let request = pb::WatchTilesRequest {
            map: map.to_string(),
            region: Some(cell_box_to_wire(region)),
            include_cells,
        };
        Ok(self.raw.clone().watch_tiles(request).await?.into_inner())
    }

    /// Stores frames; returns (stored, duplicates). Safe to retry: the
    /// server skips sequences it has.
    pub async fn publish_frames(
        &self,
        frames: Vec<pb::SonarFrame>,
    ) -> Result<(u32, u32), ClientError> {
        let request = pb::PublishFramesRequest { frames };
        let reply = self
            .unary(request, |mut raw, request| async move {
                raw.publish_frames(request).await
            })
            .await?;
        Ok((reply.stored, reply.duplicates))
    }

    /// A robot's stored frames in `from..=to` (0 = open).
    pub async fn read_frames(
        &self,
        robot: &str,
        from: u64,
        to: u64,
    ) -> Result<Vec<pb::SonarFrame>, ClientError> {
        let request = pb::ReadFramesRequest {
            robot: robot.to_string(),
            from_sequence: from,
            to_sequence: to,
            limit: 0,
        };
        let mut stream = self.raw.clone().read_frames(request).await?.into_inner();
        let mut out = Vec::new();
        while let Some(frame) = stream.next().await {
            out.push(frame?);
        }
        Ok(out)
    }

    /// Streams a robot's stored frames from `from_sequence` on, then its
    /// new frames as they are published (0: only frames published from now
    /// on).
    pub async fn subscribe_frames(
        &self,
        robot: &str,
        from_sequence: u64,
    ) -> Result<tonic::Streaming<pb::SonarFrame>, ClientError> {
        let request = pb::SubscribeFramesRequest {
            robot: robot.to_string(),
            from_sequence,
        };
        Ok(self
            .raw
            .clone()
            .subscribe_frames(request)
            .await?
            .into_inner())
    }

    /// The robots whose frames the server holds, with their sequence
    /// ranges.
    pub async fn robots(&self) -> Result<Vec<pb::RobotFrames>, ClientError> {
        Ok(self
            .unary((), |mut raw, ()| async move {
                raw.list_robots(pb::ListRobotsRequest {}).await
            })
            .await?
            .robots)
    }

    /// Stores `rig` on the server, so that consumers of this robot's frames
    /// read them with its geometry. A built-in rig, or the same rig stored
    /// before, is accepted as it is; a different rig under a known name is
    /// refused (ALREADY_EXISTS).
    pub async fn put_rig(&self, rig: &Rig) -> Result<(), ClientError> {
        let wire = rig_to_wire(rig);
        self.unary(wire, |mut raw, wire| async move { raw.put_rig(wire).await })
            .await?;
        Ok(())
    }

    /// Stores an explorer's current goal on its map, replacing its earlier
    /// one. Safe to retry: the same goal again changes nothing.
    pub async fn publish_goal(&self, goal: pb::ExplorationGoal) -> Result<(), ClientError> {
        self.unary(
            goal,
            |mut raw, goal| async move { raw.publish_goal(goal).await },
        )
        .await?;
        Ok(())
    }

    /// Every explorer's latest goal on `map`, active or given up.
    pub async fn goals(&self, map: &str) -> Result<Vec<pb::ExplorationGoal>, ClientError> {
        let request = pb::ListGoalsRequest {
            map: map.to_string(),
        };
        Ok(self
            .unary(request, |mut raw, request| async move {
                raw.list_goals(request).await
            })
            .await?
            .goals)
    }

    /// The rig a frame's `rig` field names (empty: the Scout's), as the
    /// server knows it.
    pub async fn rig(&self, frame_rig: &str) -> Result<Rig, ClientError> {
        let name = frame_rig_name(frame_rig).to_owned();
        let wire = self
            .unary(name, |mut raw, name| async move {
                raw.get_rig(pb::RigRef { name }).await
            })
            .await?;
        rig_from_wire(&wire).map_err(|e| ClientError::wire("rig", e.to_string()))
    }

    /// Every rig the server knows.
    pub async fn rigs(&self) -> Result<Vec<Rig>, ClientError> {
        let wires = self
            .raw
            .clone()
            .list_rigs(pb::ListRigsRequest {})
            .await?
            .into_inner()
            .rigs;
        wires
            .iter()
            .map(|w| rig_from_wire(w).map_err(|e| ClientError::wire("rigs", e.to_string())))
            .collect()
    }

    /// Stores a pose estimate.
    pub async fn publish_pose(&self, estimate: pb::PoseEstimate) -> Result<(), ClientError> {
        self.unary(estimate, |mut raw, estimate| async move {
            raw.publish_pose(estimate).await
        })
        .await?;
        Ok(())
    }

    /// A robot's stored pose estimates for frames `from..=to` (0 = open),
    /// in frame order, on whatever map each was made.
    pub async fn read_poses(
        &self,
        robot: &str,
        from: u64,
        to: u64,
    ) -> Result<Vec<pb::PoseEstimate>, ClientError> {
        let request = pb::ReadPosesRequest {
            robot: robot.to_string(),
            from_sequence: from,
            to_sequence: to,
        };
        let mut stream = self.raw.clone().read_poses(request).await?.into_inner();
        let mut out = Vec::new();
        while let Some(pose) = stream.next().await {
            out.push(pose?);
        }
        Ok(out)
    }

    /// Opens a batching, resending update stream for `client_id` on `map`,
    /// continuing after the last sequence the server applied for it.
    pub async fn updates(
        &self,
        map: &str,
        client_id: &str,
        config: UpdateSenderConfig,
    ) -> Result<UpdateSender, ClientError> {
        let info = self.map_info(map).await?;
        let last = self.update_cursor(map, client_id).await?;
        let first = last.checked_add(1).ok_or_else(|| {
            ClientError::Config(format!(
                "client {client_id:?} on map {map:?} has applied batch sequence {last}, \
                 the last there is: use another client id"
            ))
        })?;
        UpdateSender::start(self.clone(), info, client_id.to_string(), first, config)
    }
}
