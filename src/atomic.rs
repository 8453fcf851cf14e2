//! Atomic replacement of output files: write a temporary file in the same directory, `fsync`
//! it, then rename it over the target, so a reader (or a crash) never sees a partial file.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// An output file that cannot be written, and why.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {source}", path.display())]
pub struct OutputError {
    pub path: PathBuf,
    #[source]
    pub source: io::Error,
}

impl OutputError {
    /// `map_err` for a write of `path`.
    pub fn at(path: &Path) -> impl FnOnce(io::Error) -> OutputError {
        let path = path.to_owned();
        move |source| OutputError { path, source }
    }
}

/// Replaces `path` with `bytes` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Replaces `path` with `bytes` atomically, the new file readable and writable by its owner
/// only (mode 0600 from its creation: a secret is never readable by others, not even for a
/// moment).
pub fn write_atomic_private(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_mode(path, 0o600, |w| w.write_all(bytes))
}

/// Replaces `path` atomically with what `fill` writes (streamed through a buffer: a large
/// output is never held in memory whole).
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    write_atomic_mode(path, 0o666, fill)
}

/// [`write_atomic_with`], the new file created with `mode` (before the umask).
fn write_atomic_mode(
    path: &Path,
    mode: u32,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = match dir {
        Some(d) => d.join(&tmp_name),
        None => tmp_name.into(),
    };
    let result = (|| {
        use std::os::unix::fs::OpenOptionsExt;
        // A temporary file left by a crash keeps its mode: made anew.
        remove_if_present(&tmp)?;
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(mode)
            .open(&tmp)?;
        let mut w = io::BufWriter::with_capacity(1 << 16, file);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_data()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Removes `p`; a file already absent is not an error.
pub fn remove_if_present(p: &Path) -> io::Result<()> {
    match std::fs::remove_file(p) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

/// Shifts the numbered generations of a rotated file: `name(keep)` is deleted, then
/// `name(k)` → `name(k + 1)` down to `name(0)` (the current file) → `name(1)`; with `keep` = 0
/// the current file is deleted. Absent generations are skipped.
pub fn shift_generations(name: impl Fn(usize) -> PathBuf, keep: usize) -> io::Result<()> {
    remove_if_present(&name(keep))?;
    for k in (0..keep).rev() {
        match std::fs::rename(name(k), name(k + 1)) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
    }
    Ok(())
}

/// Removes the temporary files a killed writer left in `dir` (`.NAME.tmpPID`, of another
/// process than this one); returns how many.
pub fn remove_stale(dir: &Path) -> io::Result<usize> {
    let ours = format!(".tmp{}", std::process::id());
    let mut removed = 0;
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        let stale = name.starts_with('.')
            && name
                .rsplit_once(".tmp")
                .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
            && !name.ends_with(&ours);
        if stale && e.file_type()?.is_file() {
            std::fs::remove_file(e.path())?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Writes `value` as JSON (indented when `pretty`), atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T, pretty: bool) -> io::Result<()> {
    write_atomic_with(path, |w| {
        if pretty {
            serde_json::to_writer_pretty(&mut *w, value)
        } else {
            serde_json::to_writer(&mut *w, value)
        }
        .map_err(io::Error::other)?;
        w.write_all(b"\n")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("sfs-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("report.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("report.json")]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_temporaries_of_a_killed_writer_are_removed_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("sfs-atomic-stale-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let keep = [
            "latest.glb".to_string(),
            ".hidden".into(),
            ".notes.tmpx".into(),
            format!(".report.json.tmp{}", std::process::id()),
        ];
        for n in keep.iter().chain([&".latest.glb.tmp12".to_string()]) {
            std::fs::write(dir.join(n), b"x").unwrap();
        }
        assert_eq!(remove_stale(&dir).unwrap(), 1);
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        let mut expected = keep.to_vec();
        expected.sort();
        assert_eq!(names, expected);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
