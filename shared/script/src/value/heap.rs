//! Shared, accounted payloads: what a program's strings, lists, tuples, dicts and
//! sets hold, and the live memory budget they are counted against.
//!
//! A payload is reference-counted ([`Heap`]): assigning, reading a name, passing
//! an argument, repeating a list or testing `in` shares it instead of copying its
//! items. Payloads are still values, not objects: changing one that is shared
//! (`b = a; b.append(1)`) copies it first (copy on write), so `a` keeps what it had;
//! see `docs/compatibility.md`.
//!
//! Every payload charges its bytes to the meter of the run on this thread when it
//! is made and gives them back when it is dropped, so the meter holds what the
//! program holds now (not what it ever allocated). Operations whose result size is
//! known before they build it ([`reserve`]) fail with `MemoryError` before
//! allocating; everything else is checked right after ([`check`]).
//! The meter is thread-local because a run never leaves its thread and values are
//! not `Send`; [`MeterScope`] starts one run's accounting and restores the previous.

use std::cell::{Cell, RefCell};
use std::fmt;
use std::hash::{Hash, Hasher};
use std::ops::{Deref, DerefMut};
use std::rc::Rc;
use std::sync::Arc;

use indexmap::{IndexMap, IndexSet};

use super::Value;
use crate::error::{ErrorKind, ScriptError};
use crate::pool::{MemoryPool, CHUNK};

/// A dict's table: insertion order kept, keys hashed as Python hashes them.
pub(crate) type DictMap = IndexMap<Key, Value>;

/// A set's table, in insertion order.
pub(crate) type SetMap = IndexSet<Key>;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
    static LIMIT: Cell<usize> = const { Cell::new(usize::MAX) };
    static OVERFLOW: Cell<bool> = const { Cell::new(false) };
    /// The pool the run shares with others, if any, and the bytes it has taken from it
    /// (`usize::MAX` without a pool, so the check on every charge is one comparison).
    static POOL: RefCell<Option<Arc<MemoryPool>>> = const { RefCell::new(None) };
    static TAKEN: Cell<usize> = const { Cell::new(usize::MAX) };
    static POOL_OUT: Cell<bool> = const { Cell::new(false) };
}

/// Makes sure the run has taken `live` bytes from its pool, taking more in chunks;
/// false when the pool has no more.
fn cover(live: usize) -> bool {
    let taken = TAKEN.with(Cell::get);
    if live <= taken {
        return true;
    }
    POOL.with(|pool| match pool.borrow().as_ref() {
        None => true,
        Some(pool) => {
            let want = (live - taken).div_ceil(CHUNK).saturating_mul(CHUNK);
            let ok = pool.take(want);
            if ok {
                TAKEN.with(|t| t.set(taken + want));
            }
            ok
        }
    })
}

fn pool_error() -> ScriptError {
    let total = POOL.with(|pool| pool.borrow().as_ref().map_or(0, |pool| pool.total()));
    ScriptError::new(
        ErrorKind::Memory,
        format!(
            "the programs running at once would hold more than {} MiB together (the total interpreter memory budget)",
            total >> 20
        ),
    )
}

/// Counts `bytes` as held now.
fn charge(bytes: usize) {
    let live = LIVE.with(|l| {
        let live = l.get().saturating_add(bytes);
        l.set(live);
        live
    });
    PEAK.with(|p| p.set(p.get().max(live)));
    if !cover(live) {
        POOL_OUT.with(|o| o.set(true));
    }
}

/// Gives `bytes` back.
fn free(bytes: usize) {
    LIVE.with(|l| l.set(l.get().saturating_sub(bytes)));
}

/// The bytes the run on this thread holds now.
pub(crate) fn live() -> usize {
    LIVE.with(Cell::get)
}

/// The most bytes the run on this thread has held at once.
pub(crate) fn peak() -> usize {
    PEAK.with(Cell::get)
}

fn memory_error(limit: usize) -> ScriptError {
    ScriptError::new(ErrorKind::Memory, format!("the program would hold more than {} MiB", limit >> 20))
}

/// Fails with `MemoryError` when `bytes` more would pass the budget; call it before
/// building a value whose size is known.
///
/// # Errors
///
/// `MemoryError` naming the budget.
pub(crate) fn reserve(bytes: usize) -> Result<(), ScriptError> {
    let limit = LIMIT.with(Cell::get);
    let after = live().saturating_add(bytes);
    if after > limit {
        return Err(memory_error(limit));
    }
    if !cover(after) {
        return Err(pool_error());
    }
    Ok(())
}

/// Text to be made of `bytes` bytes, reserved (see [`reserve`]).
///
/// # Errors
///
/// `MemoryError` naming the budget.
pub(crate) fn reserve_text(bytes: usize) -> Result<(), ScriptError> {
    reserve(bytes)
}

/// A list or tuple of `items` items, reserved (see [`reserve`]).
///
/// # Errors
///
/// `MemoryError` naming the budget.
pub(crate) fn reserve_items(items: usize) -> Result<(), ScriptError> {
    reserve(items.saturating_mul(SLOT))
}

/// Reserves `bytes` and counts them as held until the run ends (printed output).
///
/// # Errors
///
/// `MemoryError` naming the budget.
pub(crate) fn hold(bytes: usize) -> Result<(), ScriptError> {
    reserve(bytes)?;
    charge(bytes);
    Ok(())
}

/// Gives back bytes taken with [`hold`].
pub(crate) fn release(bytes: usize) {
    free(bytes);
}

/// The bytes left before the budget.
pub(crate) fn room() -> usize {
    LIMIT.with(Cell::get).saturating_sub(live())
}

/// Notes that text written without a way to fail (an error message's `repr`) was
/// cut at the budget; the next [`check`] fails.
pub(crate) fn overflowed() {
    OVERFLOW.with(|o| o.set(true));
}

/// Fails with `MemoryError` when what the run holds has passed the budget.
///
/// # Errors
///
/// `MemoryError` naming the budget.
pub(crate) fn check() -> Result<(), ScriptError> {
    if OVERFLOW.with(|o| o.replace(false)) {
        return Err(memory_error(LIMIT.with(Cell::get)));
    }
    if POOL_OUT.with(|o| o.replace(false)) {
        return Err(pool_error());
    }
    reserve(0)
}

/// One run's accounting on this thread: starts at zero with `limit` bytes, and gives
/// the previous accounting back when dropped (runs do not nest, but tests may).
#[derive(Debug)]
pub(crate) struct MeterScope {
    saved: (usize, usize, usize),
    saved_pool: (Option<Arc<MemoryPool>>, usize),
}

impl MeterScope {
    /// One run's accounting against its own `limit` and, when given, a `pool` shared
    /// with other runs.
    pub(crate) fn enter(limit: usize, pool: Option<Arc<MemoryPool>>) -> MeterScope {
        let saved = (live(), peak(), LIMIT.with(Cell::get));
        OVERFLOW.with(|o| o.set(false));
        POOL_OUT.with(|o| o.set(false));
        LIVE.with(|l| l.set(0));
        PEAK.with(|p| p.set(0));
        LIMIT.with(|l| l.set(limit));
        let taken = if pool.is_some() { 0 } else { usize::MAX };
        let saved_pool = (POOL.with(|p| p.replace(pool)), TAKEN.with(|t| t.replace(taken)));
        MeterScope { saved, saved_pool }
    }
}

impl Drop for MeterScope {
    fn drop(&mut self) {
        let (live, peak, limit) = self.saved;
        LIVE.with(|l| l.set(live));
        PEAK.with(|p| p.set(peak));
        LIMIT.with(|l| l.set(limit));
        let (pool, taken) = (self.saved_pool.0.take(), self.saved_pool.1);
        let ours = POOL.with(|p| p.replace(pool));
        let our_taken = TAKEN.with(|t| t.replace(taken));
        if let Some(ours) = ours {
            ours.give(our_taken);
        }
        POOL_OUT.with(|o| o.set(false));
    }
}

/// The bytes one value slot takes (in a list, a tuple, a variable).
pub(crate) const SLOT: usize = std::mem::size_of::<Value>();

/// What a payload weighs, and how deeply it nests other payloads.
pub(crate) trait Payload: Clone + Default {
    /// The bytes it holds, not counting the payloads it shares.
    fn bytes(&self) -> usize;
    /// 0 for text; one more than its deepest item for containers.
    fn depth(&self) -> u32;
}

impl Payload for String {
    fn bytes(&self) -> usize {
        self.capacity()
    }
    fn depth(&self) -> u32 {
        0
    }
}

impl Payload for Vec<Value> {
    fn bytes(&self) -> usize {
        self.capacity().saturating_mul(SLOT)
    }
    fn depth(&self) -> u32 {
        1 + self.iter().map(Value::depth).max().unwrap_or(0)
    }
}

/// A hash table's own cost per entry besides the slots: the stored hash and the index.
const TABLE_ENTRY: usize = 2 * std::mem::size_of::<usize>();

impl Payload for DictMap {
    fn bytes(&self) -> usize {
        self.capacity().saturating_mul(2 * SLOT + TABLE_ENTRY)
    }
    fn depth(&self) -> u32 {
        1 + self.iter().map(|(k, v)| k.0.depth().max(v.depth())).max().unwrap_or(0)
    }
}

impl Payload for SetMap {
    fn bytes(&self) -> usize {
        self.capacity().saturating_mul(SLOT + TABLE_ENTRY)
    }
    fn depth(&self) -> u32 {
        1 + self.iter().map(|k| k.0.depth()).max().unwrap_or(0)
    }
}

/// A payload and what it was charged.
struct Tracked<T: Payload> {
    data: T,
    bytes: usize,
    depth: u32,
}

impl<T: Payload> Tracked<T> {
    fn new(data: T) -> Tracked<T> {
        let bytes = data.bytes();
        let depth = data.depth();
        charge(bytes);
        Tracked { data, bytes, depth }
    }
}

impl<T: Payload> Clone for Tracked<T> {
    fn clone(&self) -> Tracked<T> {
        let data = self.data.clone();
        let bytes = data.bytes();
        charge(bytes);
        Tracked { data, bytes, depth: self.depth }
    }
}

impl<T: Payload> Drop for Tracked<T> {
    fn drop(&mut self) {
        free(self.bytes);
    }
}

/// A shared, accounted payload; see the module doc.
pub(crate) struct Heap<T: Payload>(Rc<Tracked<T>>);

impl<T: Payload> Heap<T> {
    pub(crate) fn new(data: T) -> Heap<T> {
        Heap(Rc::new(Tracked::new(data)))
    }

    /// How deeply it nests payloads (0 for text).
    pub(crate) fn depth(&self) -> u32 {
        self.0.depth
    }

    /// Whether two handles share one payload (Python's `is` for containers).
    pub(crate) fn ptr_eq(a: &Heap<T>, b: &Heap<T>) -> bool {
        Rc::ptr_eq(&a.0, &b.0)
    }

    /// The payload to change, copied first when it is shared; its weight is counted
    /// again when the guard is dropped.
    pub(crate) fn make_mut(&mut self) -> HeapMut<'_, T> {
        HeapMut(Rc::make_mut(&mut self.0))
    }

    /// The payload, copied first when it is shared, to change its items in place
    /// without changing how many it holds (its weight is not counted again).
    pub(crate) fn items_mut(&mut self) -> &mut T {
        &mut Rc::make_mut(&mut self.0).data
    }

    /// Notes that an item now nests `depth` levels (after it changed in place).
    pub(crate) fn raise_depth(&mut self, depth: u32) {
        if depth.saturating_add(1) > self.0.depth {
            Rc::make_mut(&mut self.0).depth = depth.saturating_add(1);
        }
    }

    /// The payload itself when this is its only handle, else a copy.
    pub(crate) fn into_inner(self) -> T {
        match Rc::try_unwrap(self.0) {
            Ok(mut tracked) => std::mem::take(&mut tracked.data),
            Err(shared) => shared.data.clone(),
        }
    }
}

impl<T: Payload> Clone for Heap<T> {
    fn clone(&self) -> Heap<T> {
        Heap(Rc::clone(&self.0))
    }
}

impl<T: Payload> Deref for Heap<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0.data
    }
}

impl<T: Payload + PartialEq> PartialEq for Heap<T> {
    fn eq(&self, other: &Heap<T>) -> bool {
        Rc::ptr_eq(&self.0, &other.0) || self.0.data == other.0.data
    }
}

impl<T: Payload + fmt::Debug> fmt::Debug for Heap<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.data.fmt(f)
    }
}

impl PartialEq<str> for Heap<String> {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for Heap<String> {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

impl fmt::Display for Heap<String> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self)
    }
}

/// A payload being changed; see [`Heap::make_mut`].
pub(crate) struct HeapMut<'a, T: Payload>(&'a mut Tracked<T>);

impl<T: Payload> HeapMut<'_, T> {
    /// Notes that `item` now lives inside, for the nesting depth.
    pub(crate) fn adopt(&mut self, item: &Value) {
        self.0.depth = self.0.depth.max(item.depth().saturating_add(1));
    }
}

impl<T: Payload> Deref for HeapMut<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0.data
    }
}

impl<T: Payload> DerefMut for HeapMut<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        &mut self.0.data
    }
}

impl<T: Payload> Drop for HeapMut<'_, T> {
    fn drop(&mut self) {
        let now = self.0.data.bytes();
        let before = std::mem::replace(&mut self.0.bytes, now);
        if now > before {
            charge(now - before);
        } else {
            free(before - now);
        }
    }
}

/// A dict key or set item: hashed and compared as Python does (`1`, `1.0` and
/// `True` are one key; a tuple hashes by its items).
#[derive(Debug, Clone)]
pub(crate) struct Key(pub(crate) Value);

// `PartialEq` for `Key` is Python's equality, `ops::equal`: implemented in the parent
// module, so that this module and `ops` (which builds on the heap) do not name each other.

impl Eq for Key {}

impl Hash for Key {
    fn hash<H: Hasher>(&self, state: &mut H) {
        hash_value(&self.0, state);
    }
}

/// Hashes `v` so that values [`super::ops::equal`] calls equal hash alike.
fn hash_value<H: Hasher>(v: &Value, state: &mut H) {
    const INT_RANGE: std::ops::Range<f64> = -9.223_372_036_854_776e18..9.223_372_036_854_776e18;
    match v {
        Value::Bool(b) => {
            state.write_u8(1);
            state.write_i64(i64::from(*b));
        }
        Value::Int(i) => {
            state.write_u8(1);
            state.write_i64(*i);
        }
        // An integral float equals the int of its value, so it hashes as that int.
        Value::Float(f) if f.fract() == 0.0 && INT_RANGE.contains(f) => {
            state.write_u8(1);
            state.write_i64(*f as i64);
        }
        Value::Float(f) => {
            state.write_u8(2);
            state.write_u64(f.to_bits());
        }
        Value::Str(s) => {
            state.write_u8(3);
            s.as_str().hash(state);
        }
        Value::Tuple(items) => {
            state.write_u8(4);
            state.write_usize(items.len());
            for item in items.iter() {
                hash_value(item, state);
            }
        }
        // Named tuples equal the plain tuple of their fields.
        Value::Point(a, b) | Value::Size(a, b) => {
            state.write_u8(4);
            state.write_usize(2);
            hash_value(&Value::Int(*a), state);
            hash_value(&Value::Int(*b), state);
        }
        // `type(1) == int`: a class and the builtin of its name are equal.
        Value::Type(name) | Value::Function { module: "", name } => {
            state.write_u8(5);
            name.hash(state);
        }
        // Everything else is equal only to values of its own type: hashing the type
        // alone is coarse but consistent.
        other => {
            state.write_u8(6);
            other.type_name().hash(state);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_give_their_bytes_back_when_dropped() {
        let _scope = MeterScope::enter(1 << 20, None);
        let text = Heap::new("a".repeat(1000));
        assert!(live() >= 1000);
        let shared = text.clone();
        let held = live();
        drop(text);
        assert_eq!(live(), held, "a shared payload stays counted while a handle holds it");
        drop(shared);
        assert_eq!(live(), 0);
        assert!(peak() >= 1000);
    }

    #[test]
    fn changing_a_shared_payload_copies_it_and_counts_the_copy() {
        let _scope = MeterScope::enter(1 << 20, None);
        let a = Heap::new(vec![Value::Int(1); 10]);
        let mut b = a.clone();
        b.make_mut().push(Value::Int(2));
        assert_eq!(a.len(), 10);
        assert_eq!(b.len(), 11);
        assert!(live() >= 21 * SLOT);
        drop((a, b));
        assert_eq!(live(), 0);
    }

    #[test]
    fn the_budget_refuses_before_building() {
        let _scope = MeterScope::enter(1000, None);
        assert!(reserve_text(999).is_ok());
        let err = reserve_items(1000).unwrap_err();
        assert_eq!(err.kind, ErrorKind::Memory);
        assert!(check().is_ok());
    }

    #[test]
    fn equal_keys_are_one_key() {
        let mut map = DictMap::new();
        map.insert(Key(Value::Int(1)), Value::None);
        map.insert(Key(Value::Float(1.0)), Value::Int(2));
        map.insert(Key(Value::Bool(true)), Value::Int(3));
        assert_eq!(map.len(), 1);
        assert_eq!(map.get(&Key(Value::Int(1))), Some(&Value::Int(3)));
        let tuple = Value::Tuple(Heap::new(vec![Value::Int(3), Value::Int(4)]));
        map.insert(Key(tuple), Value::None);
        assert!(map.contains_key(&Key(Value::Point(3, 4))));
    }
}
