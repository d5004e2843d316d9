//! The rigs the server knows: the built-in ones and those stored with
//! `PutRig`, held in memory so that checking a frame against its rig costs
//! a map lookup. A name means one rig for the life of the data directory:
//! storing a different rig under a known name is refused.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, RwLock};

use deog_proto::rig::{rig_from_wire, rig_to_wire};
use deog_proto::v1 as pb;
use deog_rig::{BUILT_IN_RIGS, Rig, built_in_rig};
use prost::Message as _;

use crate::error::StoreError;
use crate::store::Store;

/// Every rig the server knows, by name.
#[derive(Debug)]
pub struct RigRegistry {
    known: RwLock<HashMap<String, Arc<Rig>>>,
    /// Held across a `put`'s check and write, so two different rigs sent
    /// under one name at once cannot both land.
    writing: Mutex<()>,
}

impl RigRegistry {
    /// The built-in rigs and every rig in `store`.
    pub fn load<S: Store + ?Sized>(store: &S) -> Result<Self, StoreError> {
        let mut known = HashMap::new();
        for (name, _) in BUILT_IN_RIGS {
            let rig = built_in_rig(name).expect("a built-in rig");
            known.insert(name.to_owned(), Arc::new(rig));
        }
        known.extend(stored_rigs(store)?);
        Ok(Self {
            known: RwLock::new(known),
            writing: Mutex::new(()),
        })
    }

    /// The rig called `name`, looking in `store` too when it is not known
    /// here: on a store shared by several servers, another one may have
    /// stored it. Blocks on the store only for a name not known here.
    pub fn find<S: Store + ?Sized>(
        &self,
        store: &S,
        name: &str,
    ) -> Result<Option<Arc<Rig>>, StoreError> {
        if let Some(rig) = self.get(name) {
            return Ok(Some(rig));
        }
        self.refresh(store)?;
        Ok(self.get(name))
    }

    /// Learns the rigs stored in `store` since this registry was loaded
    /// (by another server sharing it).
    pub fn refresh<S: Store + ?Sized>(&self, store: &S) -> Result<(), StoreError> {
        let stored = stored_rigs(store)?;
        let mut known = self.known.write().unwrap_or_else(|e| e.into_inner());
        for (name, rig) in stored {
            known.entry(name).or_insert(rig);
        }
        Ok(())
    }

    /// The rig called `name`, if the server knows one.
    pub fn get(&self, name: &str) -> Option<Arc<Rig>> {
        self.known
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(name)
            .cloned()
    }

    /// Every rig: the built-in ones in their order, then the stored ones by
    /// name.
    pub fn list(&self) -> Vec<Arc<Rig>> {
        let known = self.known.read().unwrap_or_else(|e| e.into_inner());
        let mut stored: Vec<&Arc<Rig>> = known
            .iter()
            .filter(|(name, _)| !deog_rig::is_built_in(name))
            .map(|(_, rig)| rig)
            .collect();
        stored.sort_by(|a, b| a.name().cmp(b.name()));
        BUILT_IN_RIGS
            .iter()
            .filter_map(|(name, _)| known.get(*name))
            .chain(stored)
            .cloned()
            .collect()
    }

    /// Stores `wire` durably under its name, unless a different rig has the
    /// name; the same rig again is accepted and changes nothing. Blocks on
    /// the store: call it off the async runtime.
    pub fn put<S: Store + ?Sized>(
        &self,
        store: &S,
        wire: &pb::Rig,
    ) -> Result<Arc<Rig>, StoreError> {
        let rig = rig_from_wire(wire).map_err(|e| StoreError::invalid("rig", e.to_string()))?;
        let _writing = self.writing.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(existing) = self.find(store, rig.name())? {
            return if *existing == rig {
                Ok(existing)
            } else {
                Err(StoreError::RigExists(rig.name().to_owned()))
            };
        }
        store.put_rig(rig.name(), rig_to_wire(&rig).encode_to_vec())?;
        store.flush()?;
        let rig = Arc::new(rig);
        self.known
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(rig.name().to_owned(), rig.clone());
        Ok(rig)
    }
}

/// Every rig `store` holds, decoded.
fn stored_rigs<S: Store + ?Sized>(store: &S) -> Result<Vec<(String, Arc<Rig>)>, StoreError> {
    store
        .rigs()?
        .into_iter()
        .map(|(name, bytes)| {
            let corrupt = |reason: String| StoreError::Corrupt {
                what: format!("rig {name:?}"),
                reason,
            };
            let wire = pb::Rig::decode(bytes.as_slice()).map_err(|e| corrupt(e.to_string()))?;
            let rig = rig_from_wire(&wire).map_err(|e| corrupt(e.to_string()))?;
            Ok((name, Arc::new(rig)))
        })
        .collect()
}
