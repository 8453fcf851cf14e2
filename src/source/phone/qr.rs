//! The phone page's address as a QR code: in the terminal (Unicode half blocks, two rows of
//! modules a line) and as SVG for the live view.

use qrcode::render::{svg, unicode};
use qrcode::{EcLevel, QrCode};

/// `text` as a QR code for a terminal, dark modules on a light background whatever the
/// terminal's colours (quiet zone included); `None` if it does not fit a QR code.
pub fn terminal(text: &str) -> Option<String> {
    let code = QrCode::with_error_correction_level(text, EcLevel::L).ok()?;
    Some(
        code.render::<unicode::Dense1x2>()
            .dark_color(unicode::Dense1x2::Light)
            .light_color(unicode::Dense1x2::Dark)
            .quiet_zone(true)
            .build()
            + "\n",
    )
}

/// `text` as an SVG image (black on white, 4 pixels a module).
pub fn svg(text: &str) -> Option<String> {
    let code = QrCode::with_error_correction_level(text, EcLevel::M).ok()?;
    Some(
        code.render::<svg::Color<'_>>()
            .module_dimensions(4, 4)
            .dark_color(svg::Color("#000000"))
            .light_color(svg::Color("#ffffff"))
            .build(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_url_with_a_token_fits_and_has_square_rows() {
        let url = "https://192.168.1.23:8443/phone?token=0123456789abcdef0123456789abcdef";
        let t = terminal(url).unwrap();
        let lines: Vec<&str> = t.lines().collect();
        let w = lines[0].chars().count();
        assert!(w > 21 && lines.iter().all(|l| l.chars().count() == w));
        // Two module rows a line.
        assert!(
            (lines.len() as f64 - w as f64 / 2.0).abs() <= 1.0,
            "{w} × {}",
            lines.len()
        );
        assert!(svg(url).unwrap().starts_with("<?xml"));
    }
}
