//! The page and its scripts, embedded in the binary (the view works offline: no CDN).
//! three.js 0.187.0 is vendored from the npm package `three` with its licence
//! (`src/view/assets/three/`: LICENSE, VERSION).

/// `(content type, bytes)` of `GET /`.
pub const INDEX: (&str, &[u8]) = (
    "text/html; charset=utf-8",
    include_bytes!("assets/index.html"),
);

const JS: &str = "text/javascript; charset=utf-8";

/// `(content type, bytes)` of the phone page (`GET /phone?token=…` on the phone port).
pub const PHONE_PAGE: (&str, &[u8]) = (
    "text/html; charset=utf-8",
    include_bytes!("assets/phone.html"),
);

/// The phone page's own files, served at the phone port's root: `(name, content type, bytes)`.
pub const PHONE_FILES: &[(&str, &str, &[u8])] = &[
    ("phone.js", JS, include_bytes!("assets/phone.js")),
    ("wire.js", JS, include_bytes!("assets/wire.js")),
    (
        "phone.css",
        "text/css; charset=utf-8",
        include_bytes!("assets/phone.css"),
    ),
];

/// The phone page's file `name`: its content type and bytes.
pub fn phone(name: &str) -> Option<(&'static str, &'static [u8])> {
    find(PHONE_FILES, name)
}

/// The file `name` of `files`: only those, no path reaches the file system.
fn find(
    files: &[(&str, &'static str, &'static [u8])],
    name: &str,
) -> Option<(&'static str, &'static [u8])> {
    files
        .iter()
        .find(|(p, _, _)| *p == name)
        .map(|(_, kind, body)| (*kind, *body))
}

/// Every file under `/assets/`: `(path, content type, bytes)`.
pub const FILES: &[(&str, &str, &[u8])] = &[
    ("view.js", JS, include_bytes!("assets/view.js")),
    (
        "view.css",
        "text/css; charset=utf-8",
        include_bytes!("assets/view.css"),
    ),
    (
        "three/three.module.js",
        JS,
        include_bytes!("assets/three/three.module.js"),
    ),
    (
        "three/three.core.js",
        JS,
        include_bytes!("assets/three/three.core.js"),
    ),
    (
        "three/addons/controls/OrbitControls.js",
        JS,
        include_bytes!("assets/three/addons/controls/OrbitControls.js"),
    ),
    (
        "three/addons/loaders/GLTFLoader.js",
        JS,
        include_bytes!("assets/three/addons/loaders/GLTFLoader.js"),
    ),
    (
        "three/addons/utils/BufferGeometryUtils.js",
        JS,
        include_bytes!("assets/three/addons/utils/BufferGeometryUtils.js"),
    ),
    (
        "three/addons/utils/SkeletonUtils.js",
        JS,
        include_bytes!("assets/three/addons/utils/SkeletonUtils.js"),
    ),
    (
        "three/LICENSE",
        "text/plain; charset=utf-8",
        include_bytes!("assets/three/LICENSE"),
    ),
    (
        "three/VERSION",
        "text/plain; charset=utf-8",
        include_bytes!("assets/three/VERSION"),
    ),
];

/// The asset at `path` (below `/assets/`): its content type and bytes. Only the files of
/// [`FILES`]: no path reaches the file system.
pub fn get(path: &str) -> Option<(&'static str, &'static [u8])> {
    find(FILES, path)
}
