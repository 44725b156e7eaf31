//! What every figure shares: the font, embedded so figures render the same on
//! a machine without fonts (DejaVu Sans, free licence in assets/fonts/), and
//! the PNG encoder.

use std::io;
use std::sync::Once;

static FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// Registers the embedded font as plotters' "sans-serif" (once per process).
pub fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT)
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans is a valid font"));
    });
}

/// RGB `pixels` of `size` encoded as PNG. (Encoded here with the `png`
/// crate rather than by plotters' bitmap encoder, which brings the whole
/// `image` crate and its decoders into the build.)
pub fn encode_png(pixels: &[u8], (width, height): (u32, u32)) -> io::Result<Vec<u8>> {
    let mut encoded = Vec::new();
    let mut encoder = png::Encoder::new(&mut encoded, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(io::Error::other)?;
    writer.write_image_data(pixels).map_err(io::Error::other)?;
    writer.finish().map_err(io::Error::other)?;
    Ok(encoded)
}
