//! A client that pipelines tiny batches as fast as it can, over real TCP on
//! 127.0.0.1: each batch its own HTTP/2 DATA frame, none waiting for an
//! acknowledgement. The server must slow it, never drop the connection,
//! and a watch sharing that connection must live on.

use crate::common::{TestServer, batch, create_map};
use deog_proto::v1 as pb;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio_stream::Stream;

/// One-cell batches `1..=last`, each yielded after a `Pending`, so that
/// the client's transport sends every batch in a DATA frame of its own,
/// as clients that write one message at a time do.
struct OneFramePerBatch {
    next: u64,
    last: u64,
    paused: bool,
}

impl Stream for OneFramePerBatch {
    type Item = pb::UpdateBatch;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        if self.next > self.last {
            return Poll::Ready(None);
        }
        if !self.paused {
            self.paused = true;
            cx.waker().wake_by_ref();
            return Poll::Pending;
        }
        self.paused = false;
        let sequence = self.next;
        self.next += 1;
        Poll::Ready(Some(one_cell_batch(sequence)))
    }
}

/// Batch `sequence`: one cell of tile (0, 0), a different one each time.
fn one_cell_batch(sequence: u64) -> pb::UpdateBatch {
    let index = (sequence % 64) as u16;
    let mut cells = index.to_le_bytes().to_vec();
    cells.extend_from_slice(&1i16.to_le_bytes());
    batch(
        "m",
        "piper",
        sequence,
        vec![pb::TileDelta {
            key: Some(pb::TileKey { x: 0, y: 0 }),
            encoding: pb::CellEncoding::SparseI16Le as i32,
            cells,
        }],
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tiny_batches_pipelined_without_pause_are_all_acknowledged_and_the_connection_lives() {
    // 100,000 on sled, the target; PostgreSQL commits each batch on its
    // own, and there 25,000, well past where the connection used to be
    // killed (after 5,294 and 14,897 acknowledgements), keep the suite short.
    let batches: u64 = if crate::common::on_postgres() {
        25_000
    } else {
        100_000
    };
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    // The watch shares the update stream's connection (a clone of one
    // channel is one HTTP/2 connection).
    let mut watch = client
        .clone()
        .watch_tiles(pb::WatchTilesRequest {
            map: "m".into(),
            region: Some(pb::CellBox {
                min_x: 0,
                min_y: 0,
                max_x: 7,
                max_y: 7,
            }),
            include_cells: false,
        })
        .await
        .expect("watch")
        .into_inner();
    // Read as it comes, as a client does: events left unread would fill
    // the client's own transport.
    let newest = Arc::new(AtomicU64::new(0));
    let watcher = tokio::spawn({
        let newest = newest.clone();
        async move {
            loop {
                let event = watch.message().await?;
                let version = match event.and_then(|e| e.event) {
                    Some(pb::tile_event::Event::Changed(tile)) => tile.version,
                    Some(pb::tile_event::Event::Resync(resync)) => resync.map_version,
                    Some(pb::tile_event::Event::Cleared(cleared)) => cleared.map_version,
                    None => return Ok::<_, tonic::Status>(()),
                };
                newest.fetch_max(version, Ordering::AcqRel);
            }
        }
    });
    let mut acks = client
        .apply_updates(OneFramePerBatch {
            next: 1,
            last: batches,
            paused: false,
        })
        .await
        .expect("update stream")
        .into_inner();
    let mut acknowledged = 0u64;
    loop {
        match tokio::time::timeout(Duration::from_secs(60), acks.message()).await {
            Ok(Ok(Some(ack))) => {
                acknowledged += 1;
                assert_eq!(ack.sequence, acknowledged, "acknowledgements in order");
                assert!(ack.applied, "batch {} applied", ack.sequence);
            }
            Ok(Ok(None)) => break,
            Ok(Err(status)) => {
                panic!("the update stream failed after {acknowledged} acknowledgements: {status:?}")
            }
            Err(_) => panic!("no acknowledgement for 60 s after {acknowledged}"),
        }
    }
    assert_eq!(acknowledged, batches);

    // The watch is alive: a new batch on another stream of the same
    // connection reaches it.
    let (more, error) =
        crate::common::send_batches(&mut client, vec![one_cell_batch(batches + 1)]).await;
    assert!(error.is_none() && more.len() == 1, "{error:?}");
    let target = more[0].map_version;
    let seen = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            tokio::time::sleep(Duration::from_millis(20)).await;
            if newest.load(Ordering::Acquire) >= target || watcher.is_finished() {
                break;
            }
        }
    })
    .await;
    assert!(seen.is_ok(), "the watch saw version {target} in time");
    assert!(
        !watcher.is_finished(),
        "the watch ended: {:?}",
        watcher.await
    );
    server.stop().await;
}
