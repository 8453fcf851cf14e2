//! Reading the files a command line or a configuration names (a configuration, a scene, a
//! mesh, a reference shape): only regular files, checked before they are opened (a FIFO
//! would block the open, a device never end), and only up to a size limit, also when a file
//! grows while it is read.
//!
//! ```
//! let e = sfs::named_file::read_text(std::path::Path::new("/dev/zero"), 1 << 20, "a configuration");
//! assert_eq!(e.unwrap_err().to_string(), "not a regular file");
//! ```

use std::io::{self, Read};
use std::path::Path;

/// The text of `path`, a regular file of at most `limit` bytes; `what` names the kind of
/// file in the error ("a configuration").
pub fn read_text(path: &Path, limit: u64, what: &str) -> io::Result<String> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file",
        ));
    }
    let too_big = |n: u64| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{n} bytes, more than the {limit} {what} may have"),
        )
    };
    if meta.len() > limit {
        return Err(too_big(meta.len()));
    }
    let mut text = String::new();
    std::fs::File::open(path)?
        .take(limit + 1)
        .read_to_string(&mut text)?;
    if text.len() as u64 > limit {
        return Err(too_big(text.len() as u64));
    }
    Ok(text)
}
