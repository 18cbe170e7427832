//! The one frame type at the host's image edge: a screenshot decoded once, and
//! the host's one PNG decoder and encoder.
//!
//! A [`Frame`] keeps the encoded bytes as they came (written to result files and
//! sent to models as they are) and the decoded pixels every later stage reads:
//! Set-of-Marks, annotation, the models' images, crops and zooms. Decoding goes
//! through [`Frame::decode`] only, which counts ([`decodes_on_this_thread`]) so a
//! test can hold one agent step to one decode per source image; encoding pixels
//! into PNG goes through [`encode_png`], which is `arena_shared::imaging::encode`.
//!
//! It is not an image library: the decoder is `arena_shared::fastimg::decode_rgba`
//! (size and memory limits, a guessed format), the encoder `arena_shared::imaging`.

use std::cell::Cell;
use std::sync::Arc;

use image::RgbaImage;

use arena_shared::observation::ImageFormat;

thread_local! {
    static DECODES: Cell<u64> = const { Cell::new(0) };
}

/// How many images [`Frame::decode`] has decoded on this thread (a test's
/// single-threaded runtime sees every decode of its own episode).
pub fn decodes_on_this_thread() -> u64 {
    DECODES.with(Cell::get)
}

/// A screenshot, decoded once: the bytes as they came (written to files as they
/// are) and the pixels every stage reads.
#[derive(Clone)]
pub struct Frame {
    /// The encoded image as the guest (or the VM's display) sent it, normally PNG.
    pub encoded: Arc<[u8]>,
    /// The decoded pixels.
    pub pixels: Arc<RgbaImage>,
}

impl std::fmt::Debug for Frame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Frame")
            .field("width", &self.pixels.width())
            .field("height", &self.pixels.height())
            .field("encoded_bytes", &self.encoded.len())
            .finish()
    }
}

impl PartialEq for Frame {
    fn eq(&self, other: &Frame) -> bool {
        self.encoded == other.encoded
    }
}

impl Frame {
    /// Decodes `bytes` (counted by [`decodes_on_this_thread`]).
    ///
    /// # Errors
    ///
    /// A message naming why the bytes are not an image this build reads.
    pub fn decode(bytes: Vec<u8>) -> Result<Frame, String> {
        DECODES.with(|c| c.set(c.get() + 1));
        let pixels = arena_shared::fastimg::decode_rgba(&bytes).map_err(|e| e.to_string())?;
        Ok(Frame { encoded: bytes.into(), pixels: Arc::new(pixels) })
    }

    /// A frame made from pixels (tests, benches), encoded as PNG for the files.
    pub fn from_pixels(pixels: RgbaImage) -> Frame {
        Frame { encoded: encode_png(&pixels).into(), pixels: Arc::new(pixels) }
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        self.pixels.dimensions()
    }
}

/// Pixels as PNG, through the one encoder (`arena_shared::imaging::encode`): the edge
/// where an image leaves the host as a file or a request. Empty for an image the
/// encoder refuses (a zero-sized one), with a warning.
pub fn encode_png(pixels: &RgbaImage) -> Vec<u8> {
    match arena_shared::imaging::encode(pixels, ImageFormat::Png, 100) {
        Ok(png) => png,
        Err(err) => {
            tracing::warn!(error = %err, "cannot encode an image as PNG");
            Vec::new()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_round_trips_through_the_one_encoder_and_decoder() {
        let pixels = RgbaImage::from_fn(5, 3, |x, y| image::Rgba([x as u8 * 40, y as u8 * 60, 7, 255]));
        let made = Frame::from_pixels(pixels.clone());
        let before = decodes_on_this_thread();
        let read = Frame::decode(made.encoded.to_vec()).expect("decodes");
        assert_eq!(decodes_on_this_thread() - before, 1);
        assert_eq!(*read.pixels, pixels);
        assert_eq!(read.size(), (5, 3));
        assert_eq!(read, made);
        assert!(Frame::decode(b"not an image".to_vec()).is_err());
    }
}
