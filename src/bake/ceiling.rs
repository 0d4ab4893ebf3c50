//! What the process may hold where something outside verdant limits it: the address-space limit
//! (`ulimit -v`, `RLIMIT_AS`, as batch schedulers set a job's `vmem`) and the control group's
//! memory limit (cgroup v2 `memory.max`, v1 `memory.limit_in_bytes`, as containers and
//! schedulers set it). A bake whose memory limit does not fit under them ends on a failed
//! allocation (an abort) or is killed by the kernel, with nothing said; `verdant bake` lowers its
//! default limit to fit and warns of a `--memory-mib` that does not.
//!
//! Read from Linux's `/proc` and `/sys/fs/cgroup`; elsewhere there is no ceiling.

use std::path::{Path, PathBuf};

/// What an outside limit leaves a bake's memory limit.
#[derive(Clone, Debug, PartialEq)]
pub struct Ceiling {
    /// The most a bake's limit should be, MiB: three quarters of what the outside limit leaves
    /// the process beyond what it already holds (a bake's plan counts its data, not the
    /// allocator's and the threads' overheads).
    pub mib: u64,
    /// The outside limit, MiB.
    pub limit_mib: u64,
    /// What the process already holds against it, MiB (its mapped address space, or its
    /// resident memory).
    pub used_mib: u64,
    /// What sets the limit, in words.
    pub what: String,
}

impl Ceiling {
    fn under(limit: u64, used: u64, what: String) -> Ceiling {
        Ceiling {
            mib: (limit.saturating_sub(used) / 4 * 3) >> 20,
            limit_mib: limit >> 20,
            used_mib: used >> 20,
            what,
        }
    }
}

/// The lowest ceiling that an outside limit sets on this process, or `None` where nothing
/// limits it (or it cannot be read).
pub fn process_ceiling() -> Option<Ceiling> {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let mut ceilings = Vec::new();
    if let Some(limit) = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|t| address_space_limit(&t))
    {
        let used = status_kib(&status, "VmSize:").unwrap_or(0) << 10;
        ceilings.push(Ceiling::under(
            limit,
            used,
            "the address-space limit (ulimit -v)".into(),
        ));
    }
    if let Some((limit, file)) = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|t| cgroup_limit(Path::new("/sys/fs/cgroup"), &t))
    {
        let used = status_kib(&status, "VmRSS:").unwrap_or(0) << 10;
        ceilings.push(Ceiling::under(
            limit,
            used,
            format!("the control group's memory limit ({})", file.display()),
        ));
    }
    ceilings.into_iter().min_by_key(|c| c.mib)
}

/// The soft address-space limit in `/proc/self/limits`'s text, bytes; `None` if unlimited.
pub fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    let soft = line["Max address space".len()..]
        .split_whitespace()
        .next()?;
    soft.parse().ok()
}

/// A number of kiB in `/proc/self/status`'s text, under `key` (`VmSize:`).
fn status_kib(status: &str, key: &str) -> Option<u64> {
    let line = status.lines().find_map(|l| l.strip_prefix(key))?;
    line.split_whitespace().next()?.parse().ok()
}

/// The lowest memory limit of the control groups that `/proc/self/cgroup`'s text puts the
/// process in, under the cgroup file systems mounted at `root`, with the file that sets it:
/// cgroup v2's `memory.max` of the process's group and every group above it, or v1's
/// `memory.limit_in_bytes` of its memory group (and above; where the group's folder is not
/// there, as in a container that sees its own group as the root, the root's).
pub fn cgroup_limit(root: &Path, cgroup: &str) -> Option<(u64, PathBuf)> {
    let mut found: Option<(u64, PathBuf)> = None;
    let mut consider = |file: PathBuf| {
        if let Some(limit) = std::fs::read_to_string(&file)
            .ok()
            .and_then(|t| memory_limit_value(&t))
            && found.as_ref().is_none_or(|(f, _)| limit < *f)
        {
            found = Some((limit, file));
        }
    };
    for line in cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(group)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (base, name) = if controllers.is_empty() {
            (root.to_path_buf(), "memory.max")
        } else if controllers.split(',').any(|c| c == "memory") {
            (root.join("memory"), "memory.limit_in_bytes")
        } else {
            continue;
        };
        let group = group.trim_start_matches('/');
        let mut dir = base.join(group);
        if !dir.is_dir() {
            dir = base.clone();
        }
        // The group and every group above it, to the mount's root.
        loop {
            consider(dir.join(name));
            if dir == base || !dir.pop() || !dir.starts_with(&base) {
                break;
            }
        }
    }
    found
}

/// A cgroup memory limit file's value, bytes; `None` for no limit (`max`, or v1's page-rounded
/// `i64::MAX`).
fn memory_limit_value(text: &str) -> Option<u64> {
    let v: u64 = text.trim().parse().ok()?;
    (v < 1 << 62).then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_soft_address_space_limit_is_read() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max cpu time              unlimited            unlimited            seconds   \n\
                      Max address space         307200000            unlimited            bytes     \n\
                      Max file locks            unlimited            unlimited            locks     \n";
        assert_eq!(address_space_limit(limits), Some(307_200_000));
        let unlimited = limits.replace("307200000", "unlimited");
        assert_eq!(address_space_limit(&unlimited), None);
        assert_eq!(address_space_limit(""), None);
    }

    #[test]
    fn a_ceiling_is_three_quarters_of_what_the_limit_leaves() {
        let c = Ceiling::under(1000 << 20, 200 << 20, "x".into());
        assert_eq!((c.mib, c.limit_mib, c.used_mib), (600, 1000, 200));
        // A process already over its limit has no room at all.
        assert_eq!(Ceiling::under(100 << 20, 200 << 20, "x".into()).mib, 0);
    }

    fn write(path: &Path, text: &str) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    #[test]
    fn the_lowest_limit_of_a_group_and_those_above_it_counts() {
        let root = std::env::temp_dir().join(format!("verdant-cgroup-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        // cgroup v2: the job's group has no limit, the slice above it has 1 GiB.
        write(&root.join("batch.slice/memory.max"), "1073741824\n");
        write(&root.join("batch.slice/job-7/memory.max"), "max\n");
        let v2 = "0::/batch.slice/job-7\n";
        assert_eq!(
            cgroup_limit(&root, v2),
            Some((1 << 30, root.join("batch.slice/memory.max")))
        );
        // A group whose folder is not there (a container's own view) reads the root's.
        write(&root.join("memory.max"), "536870912\n");
        assert_eq!(
            cgroup_limit(&root, "0::/elsewhere/x\n"),
            Some((1 << 29, root.join("memory.max")))
        );
        // cgroup v1: the memory controller's group; "unlimited" is i64::MAX rounded to a page.
        write(
            &root.join("memory/docker/abc/memory.limit_in_bytes"),
            "268435456\n",
        );
        write(
            &root.join("memory/memory.limit_in_bytes"),
            "9223372036854771712\n",
        );
        let v1 = "12:cpu,cpuacct:/docker/abc\n7:memory:/docker/abc\n";
        assert_eq!(
            cgroup_limit(&root, v1),
            Some((
                1 << 28,
                root.join("memory/docker/abc/memory.limit_in_bytes")
            ))
        );
        // No memory controller, no limit.
        assert_eq!(cgroup_limit(&root, "12:cpu:/docker/abc\n"), None);
        std::fs::remove_dir_all(&root).unwrap();
    }
}
