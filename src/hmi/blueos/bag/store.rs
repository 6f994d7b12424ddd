//! The settings bag's contents, sans-IO: one JSON document that Cockpit
//! reads and writes by path, as BlueOS's "bag of holdings" keeps it, with
//! who wrote what and how much each may keep.
//!
//! The document is kept as *records*: each set of a path stores one value
//! at that path, and no record lies under another (a set under a record
//! changes that record's value; a set over records replaces them). A read
//! of a path is the value inside the record that holds it, or the object
//! built from the records under it — what a read of the whole document at
//! that path would give.
//!
//! Who may write ([`Writer`]): a pilot anything; any other client (a
//! watcher, known by its address) may add values where there are none and
//! change only the records its address wrote, within a quota per address
//! and one for all watchers together, so that watchers keep their own
//! settings but can neither fill the card nor change what others see. The
//! vehicle id Cockpit keeps in the bag may be set once by anyone and then
//! changed by a pilot alone.
//!
//! Every value is kept as the JSON text its writer sent, its keys in their
//! order (`raw.rs`): Cockpit compares what it reads back with what it
//! wrote, text for text.
//!
//! Never reads a file or a clock; the caller persists [`Bag::to_file`] and
//! undoes a set ([`Bag::undo`]) when that fails.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::Value;
use serde_json::value::RawValue;

use super::path::BagPath;
use super::raw;

/// The path where Cockpit keeps the vehicle's id.
pub const VEHICLE_ID_PATH: [&str; 2] = ["cockpit", "cockpit-vehicle-id"];
/// Deepest nesting of a value (the file nests it a few levels more and
/// must read back).
pub const MAX_VALUE_DEPTH: usize = 64;

/// How much the bag keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// One value, as sent.
    pub value_bytes: usize,
    /// Every record together (values and their paths).
    pub total_bytes: usize,
    /// What one watcher's address may keep.
    pub address_bytes: usize,
    /// What all watchers together may keep.
    pub watchers_bytes: usize,
}

impl Default for Limits {
    /// A Cockpit's settings for one user are about 60 kB; a card has
    /// gigabytes, but the bag is read whole into memory at start.
    fn default() -> Self {
        Limits {
            value_bytes: 256 * 1024,
            total_bytes: 2 * 1024 * 1024,
            address_bytes: 512 * 1024,
            watchers_bytes: 1024 * 1024,
        }
    }
}

/// Who writes: a pilot (the HMI's rule: logged in, or an address `[hmi]
/// open_control` admits), or a watcher known by its address (the login
/// throttle's key: an IPv4 address, an IPv6 /64).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Writer {
    Pilot,
    Watcher(String),
}

impl Writer {
    fn owner(&self) -> Option<String> {
        match self {
            Writer::Pilot => None,
            Writer::Watcher(w) => Some(w.clone()),
        }
    }
}

/// Why a set changed nothing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BagError {
    #[error("the body is not JSON: {0}")]
    NotJson(String),
    #[error("the value is nested more than {MAX_VALUE_DEPTH} levels deep")]
    TooDeep,
    #[error("the value is {bytes} bytes; one value may have at most {max} bytes")]
    ValueTooLarge { bytes: usize, max: usize },
    #[error("the bag would hold {bytes} bytes; it holds at most {max}")]
    Full { bytes: usize, max: usize },
    #[error(
        "this address would keep {bytes} bytes in the bag; an address that is not logged in as the pilot keeps at most {max}"
    )]
    AddressQuota { bytes: usize, max: usize },
    #[error(
        "clients not logged in as the pilot would keep {bytes} bytes in the bag together; they keep at most {max}"
    )]
    WatchersFull { bytes: usize, max: usize },
    #[error(
        "{0} was written by another client: only the pilot (logged in) may change it — log in on the vehicle's page"
    )]
    NotYours(String),
}

/// What a set did.
#[derive(Debug, Clone, PartialEq)]
pub enum Written {
    /// The value was there already: nothing to store.
    Unchanged,
    /// Changed; [`Bag::undo`] puts it back.
    Changed(Undo),
}

/// How to put a set back (when it could not be stored).
#[derive(Debug, Clone, PartialEq)]
pub struct Undo {
    remove: BagPath,
    restore: Vec<(BagPath, Record)>,
}

#[derive(Debug, Clone, PartialEq)]
struct Record {
    /// The JSON text as its writer sent it.
    value: String,
    /// The value's text and the path: what the record costs.
    bytes: usize,
    /// The watcher address that wrote it; `None`: the pilots'.
    owner: Option<String>,
}

/// The bag's contents.
#[derive(Debug, Clone, PartialEq)]
pub struct Bag {
    records: BTreeMap<BagPath, Record>,
    limits: Limits,
}

/// The file's shape: every record with its path and writer.
#[derive(Serialize, Deserialize)]
struct FileShape {
    version: u32,
    records: Vec<FileRecord>,
}

#[derive(Serialize, Deserialize)]
struct FileRecord {
    path: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    owner: Option<String>,
    value: Box<RawValue>,
}

const FILE_VERSION: u32 = 1;

impl Bag {
    pub fn new(limits: Limits) -> Bag {
        Bag {
            records: BTreeMap::new(),
            limits,
        }
    }

    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Bytes held (values and paths).
    pub fn total_bytes(&self) -> usize {
        self.records.values().map(|r| r.bytes).sum()
    }

    /// The JSON text at `path`, as a read of the whole document would find
    /// it (each record's text as written; the objects that hold records, by
    /// key).
    pub fn get(&self, path: &BagPath) -> Option<String> {
        if let Some((at, r)) = self.holder(path) {
            return raw::at(&r.value, &path.segments()[at.segments().len()..]);
        }
        let mut tree = Node::Branch(BTreeMap::new());
        let mut any = false;
        for (p, r) in self.under(path) {
            tree.put(&p.segments()[path.segments().len()..], &r.value);
            any = true;
        }
        any.then(|| tree.text())
    }

    /// Sets `path` to the JSON `body` as `writer`.
    pub fn set(
        &mut self,
        path: &BagPath,
        body: &[u8],
        writer: &Writer,
    ) -> Result<Written, BagError> {
        let max = self.limits.value_bytes;
        if body.len() > max {
            return Err(BagError::ValueTooLarge {
                bytes: body.len(),
                max,
            });
        }
        let parsed: Value =
            serde_json::from_slice(body).map_err(|e| BagError::NotJson(e.to_string()))?;
        if depth(&parsed) > MAX_VALUE_DEPTH {
            return Err(BagError::TooDeep);
        }
        let value = raw::text_of(body).ok_or_else(|| BagError::NotJson("not one value".into()))?;
        match self.holder(path).map(|(p, _)| p.clone()) {
            Some(at) if at != *path => self.set_inside(&at, path, value, writer),
            _ => self.replace(path, value, writer),
        }
    }

    /// Puts back what a set changed.
    pub fn undo(&mut self, undo: Undo) {
        self.records.remove(&undo.remove);
        self.records.extend(undo.restore);
    }

    /// The record at `path` or above it.
    fn holder(&self, path: &BagPath) -> Option<(&BagPath, &Record)> {
        let segs = path.segments();
        (1..=segs.len()).find_map(|n| {
            let prefix = BagPath::from_segments(segs[..n].to_vec()).ok()?;
            self.records.get_key_value(&prefix)
        })
    }

    /// The records strictly under `path`.
    fn under<'a>(&'a self, path: &'a BagPath) -> impl Iterator<Item = (&'a BagPath, &'a Record)> {
        self.records
            .range(path.clone()..)
            .take_while(move |(p, _)| p.within(path))
            .filter(move |(p, _)| *p != path)
    }

    /// A set under the record at `at`: that record's value changes.
    fn set_inside(
        &mut self,
        at: &BagPath,
        path: &BagPath,
        value: String,
        writer: &Writer,
    ) -> Result<Written, BagError> {
        let Some(old) = self.records.get(at).cloned() else {
            return self.replace(path, value, writer);
        };
        if let Writer::Watcher(me) = writer
            && old.owner.as_deref() != Some(me.as_str())
        {
            return Err(BagError::NotYours(at.to_string()));
        }
        let new_value = raw::put(
            Some(&old.value),
            &path.segments()[at.segments().len()..],
            &value,
        );
        if new_value == old.value {
            return Ok(Written::Unchanged);
        }
        // A pilot writing into a watcher's record makes it the pilots'.
        let owner = if *writer == Writer::Pilot {
            None
        } else {
            old.owner.clone()
        };
        let new = record(new_value, at, owner);
        self.check_room(&new, std::slice::from_ref(&old))?;
        self.records.insert(at.clone(), new);
        Ok(Written::Changed(Undo {
            remove: at.clone(),
            restore: vec![(at.clone(), old)],
        }))
    }

    /// A set where no record holds `path`: it replaces the records under it.
    fn replace(
        &mut self,
        path: &BagPath,
        value: String,
        writer: &Writer,
    ) -> Result<Written, BagError> {
        let replaced: Vec<(BagPath, Record)> = self
            .records
            .range(path.clone()..)
            .take_while(|(p, _)| p.within(path))
            .map(|(p, r)| (p.clone(), r.clone()))
            .collect();
        let vehicle_id = path.segments() == VEHICLE_ID_PATH;
        if let Writer::Watcher(me) = writer
            && let Some((p, _)) = replaced
                .iter()
                .find(|(_, r)| r.owner.as_deref() != Some(me.as_str()))
        {
            return Err(BagError::NotYours(p.to_string()));
        }
        if let [(p, r)] = replaced.as_slice()
            && p == path
            && r.value == value
        {
            return Ok(Written::Unchanged);
        }
        // The vehicle id is the vehicle's once set, whoever set it.
        let owner = if vehicle_id { None } else { writer.owner() };
        let new = record(value, path, owner);
        let old: Vec<Record> = replaced.iter().map(|(_, r)| r.clone()).collect();
        self.check_room(&new, &old)?;
        for (p, _) in &replaced {
            self.records.remove(p);
        }
        self.records.insert(path.clone(), new);
        Ok(Written::Changed(Undo {
            remove: path.clone(),
            restore: replaced,
        }))
    }

    /// Whether `new` fits in place of `old`: the bag's total, and for a
    /// watcher's record its address's quota and all watchers'.
    fn check_room(&self, new: &Record, old: &[Record]) -> Result<(), BagError> {
        let freed: usize = old.iter().map(|r| r.bytes).sum();
        let bytes = self.total_bytes() - freed + new.bytes;
        if bytes > self.limits.total_bytes && new.bytes > freed {
            return Err(BagError::Full {
                bytes,
                max: self.limits.total_bytes,
            });
        }
        let Some(me) = &new.owner else {
            return Ok(());
        };
        let held = |who: &dyn Fn(&Option<String>) -> bool| -> usize {
            let now: usize = self
                .records
                .values()
                .filter(|r| who(&r.owner))
                .map(|r| r.bytes)
                .sum();
            let gone: usize = old.iter().filter(|r| who(&r.owner)).map(|r| r.bytes).sum();
            now - gone + new.bytes
        };
        let mine = held(&|o| o.as_deref() == Some(me.as_str()));
        if mine > self.limits.address_bytes {
            return Err(BagError::AddressQuota {
                bytes: mine,
                max: self.limits.address_bytes,
            });
        }
        let watchers = held(&|o| o.is_some());
        if watchers > self.limits.watchers_bytes {
            return Err(BagError::WatchersFull {
                bytes: watchers,
                max: self.limits.watchers_bytes,
            });
        }
        Ok(())
    }

    /// The bag as its file holds it.
    pub fn to_file(&self) -> Vec<u8> {
        let shape = FileShape {
            version: FILE_VERSION,
            records: self
                .records
                .iter()
                .filter_map(|(p, r)| {
                    Some(FileRecord {
                        path: p.segments().to_vec(),
                        owner: r.owner.clone(),
                        value: RawValue::from_string(r.value.clone()).ok()?,
                    })
                })
                .collect(),
        };
        let mut bytes = serde_json::to_vec(&shape).unwrap_or_default();
        bytes.push(b'\n');
        bytes
    }

    /// The bag from its file; records that cannot be kept (a bad path, one
    /// under another) are left out and named in the warnings.
    pub fn from_file(bytes: &[u8], limits: Limits) -> Result<(Bag, Vec<String>), String> {
        let shape: FileShape = serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
        if shape.version != FILE_VERSION {
            return Err(format!(
                "version {} (this vehicle reads version {FILE_VERSION})",
                shape.version
            ));
        }
        let mut bag = Bag::new(limits);
        let mut warnings = Vec::new();
        for r in shape.records {
            let shown = r.path.join("/");
            let path = match BagPath::from_segments(r.path) {
                Ok(p) => p,
                Err(e) => {
                    warnings.push(format!("record {shown:?} left out: {e}"));
                    continue;
                }
            };
            if bag.holder(&path).is_some() || bag.under(&path).next().is_some() {
                warnings.push(format!("record {shown:?} left out: it overlaps another"));
                continue;
            }
            let rec = record(r.value.get().to_owned(), &path, r.owner);
            bag.records.insert(path, rec);
        }
        Ok((bag, warnings))
    }
}

fn record(value: String, path: &BagPath, owner: Option<String>) -> Record {
    let bytes = value.len() + path.byte_len();
    Record {
        value,
        bytes,
        owner,
    }
}

/// The objects a read builds from the records under its path.
enum Node {
    Leaf(String),
    Branch(BTreeMap<String, Node>),
}

impl Node {
    fn put(&mut self, rest: &[String], text: &str) {
        let Some((first, more)) = rest.split_first() else {
            *self = Node::Leaf(text.to_owned());
            return;
        };
        if let Node::Leaf(_) = self {
            *self = Node::Branch(BTreeMap::new());
        }
        if let Node::Branch(map) = self {
            map.entry(first.clone())
                .or_insert_with(|| Node::Branch(BTreeMap::new()))
                .put(more, text);
        }
    }

    fn text(&self) -> String {
        match self {
            Node::Leaf(t) => t.clone(),
            Node::Branch(map) => {
                let texts: Vec<(&str, String)> =
                    map.iter().map(|(k, n)| (k.as_str(), n.text())).collect();
                raw::object(texts.iter().map(|(k, t)| (*k, t.as_str())))
            }
        }
    }
}

/// How deeply a value nests (a scalar is 1).
fn depth(v: &Value) -> usize {
    // Iterative: a value comes from a client.
    let mut deepest = 0;
    let mut stack = vec![(v, 1usize)];
    while let Some((v, d)) = stack.pop() {
        deepest = deepest.max(d);
        match v {
            Value::Array(a) => stack.extend(a.iter().map(|x| (x, d + 1))),
            Value::Object(o) => stack.extend(o.values().map(|x| (x, d + 1))),
            _ => {}
        }
    }
    deepest
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
#[path = "store_tests.rs"]
mod tests;
