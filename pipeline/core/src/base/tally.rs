//! Counts keyed by a closed set of names (reject and drop reasons, source kinds, note kinds, skip
//! reasons): typed keys in memory, the names on disk, listed in the order of the names as the
//! reports and manifests always listed them (whatever order the enum declares its variants in).

use std::collections::BTreeMap;
use std::fmt;
use std::marker::PhantomData;

use serde::de::{MapAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A value of a closed set, written as a name of its own.
pub trait Named: Copy + Eq + 'static {
    /// Every value.
    const ALL: &'static [Self];

    /// The name written in datasets, reports and caches.
    fn name(self) -> &'static str;

    /// The value called `name`.
    fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|v| v.name() == name)
    }
}

/// A key of a [`Tally`]: ordered by its name, so a tally lists (and serialises) in name order.
#[derive(Clone, Copy, PartialEq, Eq)]
struct ByName<K>(K);

impl<K: Named> Ord for ByName<K> {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.name().cmp(other.0.name())
    }
}

impl<K: Named> PartialOrd for ByName<K> {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// Names are unique within a closed set, so comparing names is comparing keys.
impl<K: Named> std::borrow::Borrow<str> for ByName<K> {
    fn borrow(&self) -> &str {
        self.0.name()
    }
}

/// What a tally can be looked up by: one of its keys, or a key's name.
pub trait TallyKey<K> {
    /// The key's name.
    fn key_name(&self) -> &str;
}

impl<K: Named> TallyKey<K> for K {
    fn key_name(&self) -> &str {
        self.name()
    }
}

impl<K> TallyKey<K> for str {
    fn key_name(&self) -> &str {
        self
    }
}

/// How many of each `K`, in the order of the keys' names; serialised as a map from name to count
/// (in JSON and in the stage cache alike, as a map keyed by strings was).
#[derive(Clone, PartialEq, Eq)]
pub struct Tally<K>(BTreeMap<ByName<K>, usize>);

impl<K> Default for Tally<K> {
    fn default() -> Self {
        Tally(BTreeMap::new())
    }
}

impl<K: Named> Tally<K> {
    /// An empty tally.
    pub fn new() -> Tally<K> {
        Tally::default()
    }

    /// Counts one more `key`.
    pub fn add(&mut self, key: K) {
        self.add_n(key, 1);
    }

    /// Counts `n` more `key`.
    pub fn add_n(&mut self, key: K, n: usize) {
        *self.0.entry(ByName(key)).or_insert(0) += n;
    }

    /// Adds every count of `other`.
    pub fn merge(&mut self, other: &Tally<K>) {
        for (key, n) in other {
            self.add_n(key, n);
        }
    }

    /// The count of `key` (a key or its name), `None` when none was counted.
    pub fn get<Q: TallyKey<K> + ?Sized>(&self, key: &Q) -> Option<&usize> {
        self.0.get(key.key_name())
    }

    /// True when nothing was counted.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// How many keys were counted.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// The keys counted, in name order.
    pub fn keys(&self) -> impl Iterator<Item = K> + '_ {
        self.0.keys().map(|k| k.0)
    }

    /// The counts, in their keys' name order.
    pub fn values(&self) -> impl Iterator<Item = &usize> + '_ {
        self.0.values()
    }

    /// Every key with its count, in name order.
    pub fn iter(&self) -> Iter<'_, K> {
        Iter(self.0.iter())
    }

    /// The counts by name, for readers that take whatever names a file holds.
    pub fn to_names(&self) -> BTreeMap<String, usize> {
        self.iter()
            .map(|(k, n)| (k.name().to_string(), n))
            .collect()
    }

    /// The sum of the counts.
    pub fn total(&self) -> usize {
        self.0.values().sum()
    }
}

/// The keys of a [`Tally`] with their counts, in name order.
pub struct Iter<'a, K>(std::collections::btree_map::Iter<'a, ByName<K>, usize>);

impl<K: Copy> Iterator for Iter<'_, K> {
    type Item = (K, usize);

    fn next(&mut self) -> Option<(K, usize)> {
        self.0.next().map(|(k, n)| (k.0, *n))
    }
}

impl<'a, K: Named> IntoIterator for &'a Tally<K> {
    type Item = (K, usize);
    type IntoIter = Iter<'a, K>;

    fn into_iter(self) -> Iter<'a, K> {
        Iter(self.0.iter())
    }
}

impl<K: Named> FromIterator<(K, usize)> for Tally<K> {
    fn from_iter<I: IntoIterator<Item = (K, usize)>>(iter: I) -> Self {
        let mut tally = Tally::new();
        for (key, n) in iter {
            tally.add_n(key, n);
        }
        tally
    }
}

impl<K: Named> FromIterator<K> for Tally<K> {
    fn from_iter<I: IntoIterator<Item = K>>(iter: I) -> Self {
        let mut tally = Tally::new();
        for key in iter {
            tally.add(key);
        }
        tally
    }
}

impl<K: Named> fmt::Debug for Tally<K> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_map()
            .entries(self.0.iter().map(|(k, n)| (k.0.name(), n)))
            .finish()
    }
}

impl<K: Named> Serialize for Tally<K> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_map(self.0.iter().map(|(k, n)| (k.0.name(), n)))
    }
}

impl<'de, K: Named> Deserialize<'de> for Tally<K> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Names<K>(PhantomData<K>);

        impl<'de, K: Named> Visitor<'de> for Names<K> {
            type Value = Tally<K>;

            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a map from name to count")
            }

            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Tally<K>, A::Error> {
                let mut tally = Tally::new();
                while let Some((name, n)) = map.next_entry::<String, usize>()? {
                    let key = K::from_name(&name).ok_or_else(|| {
                        let known: Vec<&str> = K::ALL.iter().map(|k| k.name()).collect();
                        serde::de::Error::custom(format_args!(
                            "unknown name `{name}`, expected one of {}",
                            known.join(", ")
                        ))
                    })?;
                    tally.add_n(key, n);
                }
                Ok(tally)
            }
        }

        deserializer.deserialize_map(Names(PhantomData))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::{DropReason, RejectReason};

    #[test]
    fn lists_and_serialises_in_name_order_whatever_the_declaration_order() {
        // Declared `too_short` before `duplicate` before `dropped_label`... .
        let tally: Tally<DropReason> = [
            DropReason::TooShort,
            DropReason::Duplicate,
            DropReason::TooShort,
            DropReason::DroppedLabel,
        ]
        .into_iter()
        .collect();
        let names: Vec<&str> = tally.keys().map(DropReason::name).collect();
        assert_eq!(names, ["dropped_label", "duplicate", "too_short"]);
        let json = serde_json::to_string(&tally).unwrap();
        assert_eq!(json, r#"{"dropped_label":1,"duplicate":1,"too_short":2}"#);
        let strings: BTreeMap<String, usize> = serde_json::from_str(&json).unwrap();
        assert_eq!(serde_json::to_string(&strings).unwrap(), json);
        assert_eq!(
            serde_json::from_str::<Tally<DropReason>>(&json).unwrap(),
            tally
        );
        assert_eq!(tally.get(&DropReason::TooShort), Some(&2));
        assert_eq!(tally.get("duplicate"), Some(&1));
        assert_eq!(tally.total(), 4);
    }

    #[test]
    fn encodes_in_the_cache_as_a_map_keyed_by_strings_did() {
        let tally: Tally<RejectReason> =
            [RejectReason::Profile, RejectReason::Bvh, RejectReason::Bvh]
                .into_iter()
                .collect();
        let strings: BTreeMap<String, usize> =
            tally.iter().map(|(k, n)| (k.name().into(), n)).collect();
        let bytes = postcard::to_stdvec(&tally).unwrap();
        assert_eq!(bytes, postcard::to_stdvec(&strings).unwrap());
        assert_eq!(
            postcard::from_bytes::<Tally<RejectReason>>(&bytes).unwrap(),
            tally
        );
    }

    #[test]
    fn an_unknown_name_does_not_read() {
        let err = serde_json::from_str::<Tally<RejectReason>>(r#"{"bvh":1,"gremlins":2}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("gremlins"), "{err}");
    }
}
