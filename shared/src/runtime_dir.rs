//! The directories navsync keeps its runtime files in (iceoryx2's root, the simulator's and
//! the demo's pseudo-terminal links), made so that another local user cannot pre-empt them.
//!
//! A predictable path in `/tmp` (`/tmp/iceoryx2`, `/tmp/navsync`) can be created first by
//! anyone; a navsync process that then used it would let its creator read the service
//! descriptions and pseudo-terminal links, or put their own in. So every such directory is
//! created owner-only when it is missing, and checked when it is there: it must be a
//! directory (a symbolic link or another file is refused), belong to this user or to root,
//! and not be writable by other users; its parent must not be writable by others either unless
//! it is sticky (as `/tmp`), or the directory could be swapped. A directory that fails is
//! refused with an error that names it and says what to do, never used silently.
//!
//! Where they are ([`base`]): `$RUNTIME_DIRECTORY` (systemd's `RuntimeDirectory=`), else
//! `$XDG_RUNTIME_DIR/navsync` (the user's own runtime directory, 0700 by the XDG
//! specification), else `/run/navsync` for root, else `/tmp/navsync-<uid>`. iceoryx2's root
//! is [`crate::ipc::root_dir`].

use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

/// Mode of the directories navsync creates (iceoryx2's own is the same): the owner
/// everything, the group may look, others nothing.
pub const DIR_MODE: u32 = 0o750;

/// Why a runtime directory was refused.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeDirError {
    /// The operating system refused to create or inspect it.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The directory.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// It is a symbolic link or not a directory.
    #[error("{path} is not a directory of its own (a symbolic link or another kind of file): refused")]
    NotADirectory {
        /// The path.
        path: PathBuf,
    },
    /// Another user owns it.
    #[error(
        "{path} belongs to uid {owner_uid}, not to this user (uid {my_uid}) or root: refused, its owner could read or inject navsync's data; remove it or use another directory ({hint})"
    )]
    ForeignOwner {
        /// The directory.
        path: PathBuf,
        /// Its owner.
        owner_uid: u32,
        /// This process's effective user.
        my_uid: u32,
        /// Where the directory comes from (which variable to set instead).
        hint: &'static str,
    },
    /// Other users may write into it (or into its parent, which is not sticky).
    #[error(
        "{path} is writable by other users (mode {mode:04o}): refused, they could put their own files in it; remove it or `chmod o-w` it ({hint})"
    )]
    WritableByOthers {
        /// The directory (or its parent).
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
        /// Where the directory comes from.
        hint: &'static str,
    },
}

/// This process's effective user id.
pub fn effective_uid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// navsync's runtime directory (not created; see [`ensure`]): `$RUNTIME_DIRECTORY` (the first
/// when systemd lists several), else `$XDG_RUNTIME_DIR/navsync`, else `/run/navsync` for root,
/// else `/tmp/navsync-<uid>`.
pub fn base() -> PathBuf {
    base_from(
        std::env::var_os("RUNTIME_DIRECTORY").map(PathBuf::from),
        std::env::var_os("XDG_RUNTIME_DIR").map(PathBuf::from),
        effective_uid(),
    )
}

/// [`base`] from given values (pure, for tests).
pub fn base_from(runtime_directory: Option<PathBuf>, xdg_runtime_dir: Option<PathBuf>, uid: u32) -> PathBuf {
    if let Some(first) = runtime_directory
        .as_ref()
        .and_then(|d| d.to_str())
        .and_then(|d| d.split(':').find(|p| !p.is_empty()))
    {
        return PathBuf::from(first);
    }
    if let Some(x) = xdg_runtime_dir.filter(|x| x.is_absolute()) {
        return x.join("navsync");
    }
    if uid == 0 {
        PathBuf::from("/run/navsync")
    } else {
        PathBuf::from(format!("/tmp/navsync-{uid}"))
    }
}

/// Where a directory's path came from, for the error's advice.
pub const HINT: &str = "set $XDG_RUNTIME_DIR or $RUNTIME_DIRECTORY to a directory of your own";

/// Checks an existing directory as described in the [module](self) documentation.
pub fn check(path: &Path, hint: &'static str) -> Result<(), RuntimeDirError> {
    let m = std::fs::symlink_metadata(path).map_err(|source| RuntimeDirError::Io {
        path: path.to_path_buf(),
        what: "inspecting",
        source,
    })?;
    if !m.file_type().is_dir() {
        return Err(RuntimeDirError::NotADirectory {
            path: path.to_path_buf(),
        });
    }
    let me = effective_uid();
    if m.uid() != me && m.uid() != 0 {
        return Err(RuntimeDirError::ForeignOwner {
            path: path.to_path_buf(),
            owner_uid: m.uid(),
            my_uid: me,
            hint,
        });
    }
    if m.mode() & 0o002 != 0 {
        return Err(RuntimeDirError::WritableByOthers {
            path: path.to_path_buf(),
            mode: m.mode() & 0o7777,
            hint,
        });
    }
    // Its parent: others may not rename it away and put their own in its place (a sticky
    // directory such as /tmp lets only the owner rename).
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty())
        && let Ok(pm) = std::fs::metadata(parent)
        && pm.mode() & 0o002 != 0
        && pm.mode() & 0o1000 == 0
    {
        return Err(RuntimeDirError::WritableByOthers {
            path: parent.to_path_buf(),
            mode: pm.mode() & 0o7777,
            hint,
        });
    }
    Ok(())
}

/// Creates `path` with [`DIR_MODE`] when it is missing (its missing parents too, each
/// checked), then checks it; returns it.
pub fn ensure(path: &Path, hint: &'static str) -> Result<PathBuf, RuntimeDirError> {
    if std::fs::symlink_metadata(path).is_err() {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty())
            && std::fs::symlink_metadata(parent).is_err()
        {
            ensure(parent, hint)?;
        }
        match std::fs::DirBuilder::new().mode(DIR_MODE).create(path) {
            Ok(()) => {}
            // Created by a concurrent navsync process: checked below like any other.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(source) => {
                return Err(RuntimeDirError::Io {
                    path: path.to_path_buf(),
                    what: "creating",
                    source,
                });
            }
        }
    }
    check(path, hint)?;
    Ok(path.to_path_buf())
}

/// A fresh directory of this process, `name` under [`base`] (created exclusively: one that
/// exists already is an error, not reused).
pub fn private(name: &str) -> Result<PathBuf, RuntimeDirError> {
    let base = ensure(&base(), HINT)?;
    let dir = base.join(name);
    std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&dir)
        .map_err(|source| RuntimeDirError::Io {
            path: dir.clone(),
            what: "creating",
            source,
        })?;
    check(&dir, HINT)?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn the_base_follows_systemd_then_xdg_then_the_user() {
        let p = |s: &str| Some(PathBuf::from(s));
        assert_eq!(
            base_from(p("/run/navsync:/run/other"), p("/run/user/7"), 7),
            PathBuf::from("/run/navsync")
        );
        assert_eq!(
            base_from(None, p("/run/user/7"), 7),
            PathBuf::from("/run/user/7/navsync")
        );
        assert_eq!(base_from(None, p("relative"), 7), PathBuf::from("/tmp/navsync-7"));
        assert_eq!(base_from(p(""), None, 0), PathBuf::from("/run/navsync"));
        assert_eq!(base_from(None, None, 1000), PathBuf::from("/tmp/navsync-1000"));
    }

    #[test]
    fn a_world_writable_or_linked_directory_is_refused_and_a_fresh_one_made_private() {
        let scratch = std::env::temp_dir().join(format!("navsync-rtdir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&scratch);
        let made = ensure(&scratch.join("a/b"), HINT).unwrap();
        let mode = std::fs::metadata(&made).unwrap().mode() & 0o777;
        assert_eq!(mode & 0o027, 0, "{mode:o}");

        std::fs::set_permissions(&made, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = ensure(&made, HINT).unwrap_err();
        assert!(matches!(e, RuntimeDirError::WritableByOthers { .. }), "{e}");
        assert!(e.to_string().contains(&made.display().to_string()), "{e}");

        // Its child, in a parent others may write without the sticky bit.
        let e = check(&made.join("missing"), HINT).unwrap_err();
        assert!(matches!(e, RuntimeDirError::Io { .. }), "{e}");
        std::fs::create_dir(made.join("c")).unwrap();
        let e = check(&made.join("c"), HINT).unwrap_err();
        assert!(
            matches!(e, RuntimeDirError::WritableByOthers { ref path, .. } if *path == made),
            "{e}"
        );

        let link = scratch.join("link");
        std::os::unix::fs::symlink(&made, &link).unwrap();
        let e = check(&link, HINT).unwrap_err();
        assert!(matches!(e, RuntimeDirError::NotADirectory { .. }), "{e}");
        std::fs::remove_dir_all(&scratch).unwrap();
    }
}
