//! `--shard i/n`: a deterministic slice of the task list for one of `n` machines.
//!
//! Shards are 1-based (`1/2` and `2/2`), and shard `i` holds the tasks at
//! positions `i-1, i-1+n, i-1+2n, ...` of the sorted list, so every shard gets
//! a mix of domains and the sizes differ by at most one. A Kubernetes Indexed
//! Job's `JOB_COMPLETION_INDEX` is 0-based: pass `$((JOB_COMPLETION_INDEX + 1))/$N`.

use std::fmt;
use std::str::FromStr;

/// One slice of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 1-based.
    pub index: u32,
    pub count: u32,
}

impl Shard {
    /// The whole list.
    pub const ALL: Shard = Shard { index: 1, count: 1 };

    /// The items of this shard, in their order.
    pub fn select<T>(&self, items: Vec<T>) -> Vec<T> {
        let count = self.count.max(1) as usize;
        let slot = (self.index.max(1) - 1) as usize;
        items.into_iter().enumerate().filter(|(pos, _)| pos % count == slot).map(|(_, item)| item).collect()
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(text: &str) -> Result<Shard, String> {
        let (i, n) = text.split_once('/').ok_or_else(|| format!("{text:?} is not a shard: write i/n, as in 1/4"))?;
        let number = |s: &str| s.trim().parse::<u32>().ok();
        match (number(i), number(n)) {
            (Some(0), Some(_)) => {
                Err(format!("{text:?}: shards are numbered from 1 (for a 0-based index use $((INDEX + 1))/N)"))
            }
            (Some(index), Some(count)) if count >= 1 && index <= count => Ok(Shard { index, count }),
            (Some(_), Some(_)) => Err(format!("{text:?}: the shard number must be between 1 and the shard count")),
            _ => Err(format!("{text:?} is not a shard: write i/n with whole numbers, as in 1/4")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_one_based() {
        fn check(input: &str, expected: Result<(u32, u32), ()>) {
            assert_eq!(input.parse::<Shard>().map(|s| (s.index, s.count)).map_err(drop), expected, "{input:?}");
        }
        check("1/2", Ok((1, 2)));
        check(" 2 / 2 ", Ok((2, 2)));
        check("1/1", Ok((1, 1)));
        check("0/2", Err(()));
        check("3/2", Err(()));
        check("1/0", Err(()));
        check("1", Err(()));
        check("a/b", Err(()));
        assert!("0/4".parse::<Shard>().unwrap_err().contains("INDEX + 1"));
    }

    #[test]
    fn shards_partition_the_list_and_interleave() {
        let items: Vec<u32> = (0..10).collect();
        assert_eq!(Shard { index: 1, count: 3 }.select(items.clone()), [0, 3, 6, 9]);
        assert_eq!(Shard { index: 2, count: 3 }.select(items.clone()), [1, 4, 7]);
        assert_eq!(Shard { index: 3, count: 3 }.select(items.clone()), [2, 5, 8]);
        assert_eq!(Shard::ALL.select(items.clone()), items);
        let mut all: Vec<u32> = (1..=4).flat_map(|i| Shard { index: i, count: 4 }.select(items.clone())).collect();
        all.sort_unstable();
        assert_eq!(all, items, "every item is in exactly one shard");
        assert_eq!(Shard { index: 5, count: 5 }.select(vec![1, 2]), Vec::<u32>::new());
    }
}
