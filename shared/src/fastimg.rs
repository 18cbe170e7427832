//! The fast image path: the model-image size upstream's Navi agent sends, a SIMD
//! resize and a SIMD JPEG encoder, all pure Rust.
//!
//! Every Navi step resizes its screenshots to what upstream calls the "OpenAI input
//! resolution" (short side at most 768, long side at most 2048) and sends them as
//! JPEG; the guest serves JPEG and downscaled screenshots too. The `image` crate's
//! resize and JPEG encoder are scalar and several times slower than Pillow's; this
//! module uses [`fast_image_resize`] (SSE4.1/AVX2/NEON picked at run time) and
//! [`libjpeg_turbo_rs`] (a Rust port of libjpeg-turbo, the library behind Pillow's
//! JPEG, with its SIMD picked at run time), neither of which needs a C toolchain, so
//! the Windows cross build is unchanged.
//!
//! # Intended use on the host
//!
//! A step's screenshot arrives as PNG bytes; [`png_to_model_jpeg`] decodes it to RGBA,
//! sizes it with [`model_size`], resizes it with [`Filter::Bicubic`] (what upstream's
//! `image.resize((w, h))` does) and encodes JPEG, returning the bytes together with
//! the size and the scale that maps model coordinates back to screen coordinates.
//! Code that already holds the decoded image calls [`rgba_to_model_jpeg`].

use image::RgbaImage;

/// Upstream's cap on the longer side of a model image.
pub const MODEL_MAX_SIDE: u32 = 2048;
/// Upstream's cap on the shorter side of a model image.
pub const MODEL_SHORT_SIDE: u32 = 768;
/// Pillow's default JPEG quality (`Image.save(..., "JPEG")` without `quality=`).
pub const PILLOW_JPEG_QUALITY: u8 = 75;
/// JPEG stores each side in 16 bits.
pub const MAX_JPEG_SIDE: u32 = u16::MAX as u32;
/// Largest side [`png_to_model_jpeg`] decodes: four 4K screens side by side.
pub const MAX_DECODED_SIDE: u32 = 16_384;
/// Most memory one decode in [`png_to_model_jpeg`] may allocate.
pub const MAX_DECODED_BYTES: u64 = 256 << 20;

/// How the bytes of a pixel buffer are laid out: 8 bits a channel, rows packed
/// without padding, top row first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    Rgb8,
    Rgba8,
}

impl Layout {
    /// Bytes per pixel.
    pub const fn bytes(self) -> usize {
        match self {
            Layout::Rgb8 => 3,
            Layout::Rgba8 => 4,
        }
    }
}

/// The resampling filter, named after Pillow's. Each is a true convolution whose
/// support widens with the reduction factor, as Pillow's `Image.resize` does when
/// `reducing_gap` is not given, so downscaling averages every source pixel rather
/// than sampling a few.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    /// Pillow's `BOX`: the mean of the source pixels each output pixel covers.
    Box,
    /// Pillow's `BILINEAR` (the `image` crate's `Triangle`): a triangle kernel.
    Bilinear,
    /// Pillow's `BICUBIC`, the default of `Image.resize` for RGB(A) images: the cubic
    /// kernel with a = -0.5 (Catmull-Rom).
    Bicubic,
}

impl Filter {
    fn algorithm(self) -> fast_image_resize::ResizeAlg {
        use fast_image_resize::{FilterType, ResizeAlg};
        ResizeAlg::Convolution(match self {
            Filter::Box => FilterType::Box,
            Filter::Bilinear => FilterType::Bilinear,
            Filter::Bicubic => FilterType::CatmullRom,
        })
    }
}

/// Why an image could not be resized, encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum FastImgError {
    #[error("a {width}x{height} {layout:?} image needs {needed} bytes, the buffer holds {len}")]
    BufferSize { width: u32, height: u32, layout: Layout, needed: u64, len: usize },
    #[error("an image of {width}x{height} pixels has nothing to encode or resize")]
    Empty { width: u32, height: u32 },
    #[error("a {width}x{height} image is too large for JPEG ({MAX_JPEG_SIDE} pixels a side at most)")]
    TooLargeForJpeg { width: u32, height: u32 },
    #[error("resizing: {0}")]
    ResizeBuffer(#[from] fast_image_resize::ImageBufferError),
    #[error("resizing: {0}")]
    Resize(#[from] fast_image_resize::ResizeError),
    #[error("encoding JPEG: {0}")]
    Jpeg(#[from] libjpeg_turbo_rs::JpegError),
    #[error("decoding image: {0}")]
    Decode(#[from] image::ImageError),
}

/// A model-image size and the scale that produced it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSize {
    pub width: u32,
    pub height: u32,
    /// Model pixels per screen pixel (1.0 when the image is kept as it is), as upstream
    /// returns it: the product of the factors of its two steps, not the ratio of the
    /// rounded sides. Divide a model coordinate by it to get a screen coordinate.
    pub scale: f64,
}

impl ModelSize {
    /// Whether the image is sent at its own size.
    pub fn unchanged(&self, width: u32, height: u32) -> bool {
        (self.width, self.height) == (width, height)
    }
}

/// The size upstream's Navi agent resizes a `width` x `height` screenshot to: never
/// larger, the aspect ratio kept, the longer side at most [`MODEL_MAX_SIDE`] and the
/// shorter side at most [`MODEL_SHORT_SIDE`].
///
/// The arithmetic is upstream's, step for step, so the sides agree to the pixel:
/// an image already within both caps is kept; otherwise one whose longer side is over
/// 2048 is first scaled by `2048 / longer`, then one whose shorter side is still over
/// 768 by `768 / shorter`. Each step multiplies both sides by the factor in double
/// precision and rounds toward zero (Python's `int()`), so 1440x900 gives 1228x768,
/// not 1229x768. Unlike upstream, a side that would round to 0 (an image over 2048
/// times longer than wide) is kept at 1, so the result can always be encoded.
pub fn model_size(width: u32, height: u32) -> ModelSize {
    let (max, short) = (f64::from(MODEL_MAX_SIDE), f64::from(MODEL_SHORT_SIDE));
    let (mut w, mut h) = (f64::from(width), f64::from(height));
    if w <= max && h <= max && w.min(h) <= short {
        return ModelSize { width, height, scale: 1.0 };
    }
    let mut scale = 1.0;
    if w.max(h) > max {
        scale = max / w.max(h);
        (w, h) = ((w * scale).trunc(), (h * scale).trunc());
    }
    if w.min(h) > short {
        let factor = short / w.min(h);
        (w, h) = ((w * factor).trunc(), (h * factor).trunc());
        scale *= factor;
    }
    // Both are whole numbers between 0 and the source side, so they fit in a u32.
    ModelSize { width: (w as u32).max(1), height: (h as u32).max(1), scale }
}

fn check_buffer(pixels: &[u8], width: u32, height: u32, layout: Layout) -> Result<(), FastImgError> {
    if width == 0 || height == 0 {
        return Err(FastImgError::Empty { width, height });
    }
    let needed = u64::from(width) * u64::from(height) * layout.bytes() as u64;
    if (pixels.len() as u64) < needed {
        return Err(FastImgError::BufferSize { width, height, layout, needed, len: pixels.len() });
    }
    Ok(())
}

/// The resize behind [`resize`]; `use_alpha` weights colours by alpha (RGBA only).
fn resize_inner(
    pixels: &[u8],
    (width, height): (u32, u32),
    layout: Layout,
    (to_width, to_height): (u32, u32),
    filter: Filter,
    use_alpha: bool,
) -> Result<Vec<u8>, FastImgError> {
    use fast_image_resize::images::{Image, ImageRef};
    use fast_image_resize::{PixelType, ResizeOptions, Resizer};
    check_buffer(pixels, width, height, layout)?;
    if to_width == 0 || to_height == 0 {
        return Err(FastImgError::Empty { width: to_width, height: to_height });
    }
    let pixel_type = match layout {
        Layout::Rgb8 => PixelType::U8x3,
        Layout::Rgba8 => PixelType::U8x4,
    };
    let used = width as usize * height as usize * layout.bytes();
    let src = ImageRef::new(width, height, &pixels[..used], pixel_type)?;
    let mut dst = Image::new(to_width, to_height, pixel_type);
    let options = ResizeOptions::new().resize_alg(filter.algorithm()).use_alpha(use_alpha);
    Resizer::new().resize(&src, &mut dst, &options)?;
    Ok(dst.into_vec())
}

/// Resizes a `width` x `height` buffer of `layout` pixels to `to` (width, height)
/// with `filter`, returning a packed buffer of the same layout.
///
/// RGBA is resized with colours weighted by alpha (premultiplied), so transparent
/// pixels do not bleed their hidden colour; for opaque images this changes nothing.
///
/// # Errors
///
/// A buffer shorter than its size says, or a source or target side of 0.
pub fn resize(
    pixels: &[u8],
    width: u32,
    height: u32,
    layout: Layout,
    to: (u32, u32),
    filter: Filter,
) -> Result<Vec<u8>, FastImgError> {
    resize_inner(pixels, (width, height), layout, to, filter, true)
}

/// [`resize`] for an [`RgbaImage`].
///
/// # Errors
///
/// A side of `image` or of the target is 0.
pub fn resize_rgba(image: &RgbaImage, width: u32, height: u32, filter: Filter) -> Result<RgbaImage, FastImgError> {
    let out = resize(image.as_raw(), image.width(), image.height(), Layout::Rgba8, (width, height), filter)?;
    // `resize` returns exactly width * height RGBA pixels.
    Ok(RgbaImage::from_raw(width, height, out).expect("the resizer returns a full buffer"))
}

/// Encodes a `width` x `height` buffer of `layout` pixels as a baseline JPEG at
/// `quality` (clamped to 1 to 100) with 4:2:0 chroma subsampling at every quality,
/// as Pillow and the `image` crate do by default. The quantisation tables and Huffman
/// coding are libjpeg-turbo's, so the output matches what Pillow writes. The alpha of RGBA is ignored, as
/// Pillow's `convert("RGB")` drops it.
///
/// # Errors
///
/// A buffer shorter than its size says, a side of 0 or over [`MAX_JPEG_SIDE`].
pub fn encode_jpeg(
    pixels: &[u8],
    width: u32,
    height: u32,
    layout: Layout,
    quality: u8,
) -> Result<Vec<u8>, FastImgError> {
    check_buffer(pixels, width, height, layout)?;
    let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
        return Err(FastImgError::TooLargeForJpeg { width, height });
    };
    let format = match layout {
        Layout::Rgb8 => libjpeg_turbo_rs::PixelFormat::Rgb,
        // libjpeg-turbo reads the alpha byte as padding. (Its `Rgbx` means the same but
        // takes a scalar path here, four times slower.)
        Layout::Rgba8 => libjpeg_turbo_rs::PixelFormat::Rgba,
    };
    let used = width as usize * height as usize * layout.bytes();
    let subsampling = libjpeg_turbo_rs::Subsampling::S420;
    Ok(libjpeg_turbo_rs::compress(&pixels[..used], w.into(), h.into(), format, quality.clamp(1, 100), subsampling)?)
}

/// A screenshot as the model sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelJpeg {
    /// The JPEG bytes.
    pub jpeg: Vec<u8>,
    /// The size of the JPEG and the scale from screen to model pixels.
    pub size: ModelSize,
}

/// Resizes `image` to its [`model_size`] with Pillow's default [`Filter::Bicubic`]
/// (a no-op when the size is kept) and encodes it as JPEG at `quality`.
///
/// Alpha is dropped before resizing, as a screenshot converted to RGB would be.
///
/// # Errors
///
/// An image with a side of 0, or the encoder fails.
pub fn rgba_to_model_jpeg(image: &RgbaImage, quality: u8) -> Result<ModelJpeg, FastImgError> {
    let (width, height) = image.dimensions();
    let size = model_size(width, height);
    let jpeg = if size.unchanged(width, height) {
        encode_jpeg(image.as_raw(), width, height, Layout::Rgba8, quality)?
    } else {
        let to = (size.width, size.height);
        let small = resize_inner(image.as_raw(), (width, height), Layout::Rgba8, to, Filter::Bicubic, false)?;
        encode_jpeg(&small, size.width, size.height, Layout::Rgba8, quality)?
    };
    Ok(ModelJpeg { jpeg, size })
}

/// Decodes a screenshot (PNG, or JPEG) and returns it as [`rgba_to_model_jpeg`] does:
/// screenshot bytes in, the model's JPEG out.
///
/// An image claiming more than [`MAX_DECODED_SIDE`] pixels a side or
/// [`MAX_DECODED_BYTES`] of memory is refused from its header, before decoding.
///
/// # Errors
///
/// The bytes are not an image this build decodes, are over the limits, or encoding fails.
pub fn png_to_model_jpeg(png: &[u8], quality: u8) -> Result<ModelJpeg, FastImgError> {
    rgba_to_model_jpeg(&decode_rgba(png)?, quality)
}

/// Decodes a screenshot (PNG, or any format this build reads) into RGBA pixels,
/// refusing from its header an image over [`MAX_DECODED_SIDE`] pixels a side or
/// [`MAX_DECODED_BYTES`] of memory.
///
/// # Errors
///
/// The bytes are not an image this build decodes, or are over the limits.
pub fn decode_rgba(bytes: &[u8]) -> Result<RgbaImage, FastImgError> {
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(image::ImageError::IoError)?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_DECODED_SIDE);
    limits.max_image_height = Some(MAX_DECODED_SIDE);
    limits.max_alloc = Some(MAX_DECODED_BYTES);
    reader.limits(limits);
    Ok(reader.decode()?.into_rgba8())
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgba;

    #[test]
    fn model_size_follows_upstream_to_the_pixel() {
        // Expected values computed with upstream's own Python arithmetic.
        let cases = [
            ((1440, 900), (1228, 768)),
            ((900, 1440), (768, 1228)),
            ((1920, 1080), (1365, 768)),
            ((2560, 1440), (1365, 768)),
            ((3840, 2160), (1365, 768)),
            ((1366, 769), (1364, 768)),
            ((1600, 1200), (1024, 768)),
            ((1280, 1024), (960, 768)),
            ((3440, 1440), (1835, 768)),
            ((3000, 3000), (768, 768)),
            ((2049, 2049), (768, 768)),
            ((5000, 800), (2048, 327)),
            ((4096, 10), (2048, 5)),
        ];
        for ((w, h), want) in cases {
            let got = model_size(w, h);
            assert_eq!((got.width, got.height), want, "{w}x{h}");
            assert!(got.scale < 1.0, "{w}x{h} shrinks");
        }
        let s = model_size(1440, 900);
        assert!((s.scale - 768.0 / 900.0).abs() < 1e-12);
        assert!((model_size(5000, 800).scale - 0.4096).abs() < 1e-12);
    }

    #[test]
    fn model_size_never_upscales() {
        for (w, h) in [(1024, 768), (1280, 720), (1366, 768), (800, 600), (1, 1), (2048, 768), (768, 2048)] {
            assert_eq!(model_size(w, h), ModelSize { width: w, height: h, scale: 1.0 }, "{w}x{h}");
        }
    }

    #[test]
    fn model_size_keeps_a_side_of_at_least_one() {
        let s = model_size(10_000, 1);
        assert_eq!((s.width, s.height), (2048, 1));
        let s = model_size(1, 10_000);
        assert_eq!((s.width, s.height), (1, 2048));
    }

    /// A horizontal grey gradient with an opaque red square in the middle.
    fn gradient_with_square(width: u32, height: u32) -> RgbaImage {
        RgbaImage::from_fn(width, height, |x, y| {
            let (cx, cy) = (width / 2, height / 2);
            if x.abs_diff(cx) < width / 8 && y.abs_diff(cy) < height / 8 {
                Rgba([220, 30, 30, 255])
            } else {
                let v = (x * 255 / (width - 1)) as u8;
                Rgba([v, v, v, 255])
            }
        })
    }

    /// Mean RGB over the box [x0, x1) x [y0, y1) of `image`.
    fn mean(image: &RgbaImage, x0: u32, y0: u32, x1: u32, y1: u32) -> [f64; 3] {
        let mut sum = [0.0; 3];
        for y in y0..y1 {
            for x in x0..x1 {
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += f64::from(image.get_pixel(x, y).0[c]);
                }
            }
        }
        let n = f64::from((x1 - x0) * (y1 - y0));
        sum.map(|s| s / n)
    }

    fn assert_close(got: [f64; 3], want: [f64; 3], tolerance: f64, what: &str) {
        for c in 0..3 {
            assert!((got[c] - want[c]).abs() <= tolerance, "{what}: got {got:?}, want {want:?}");
        }
    }

    #[test]
    fn model_jpeg_decodes_at_the_model_size_with_its_colours() {
        let src = gradient_with_square(1440, 900);
        let out = rgba_to_model_jpeg(&src, PILLOW_JPEG_QUALITY).unwrap();
        assert_eq!((out.size.width, out.size.height), (1228, 768));
        let back = image::load_from_memory_with_format(&out.jpeg, image::ImageFormat::Jpeg).unwrap().to_rgba8();
        assert_eq!(back.dimensions(), (1228, 768));
        // The whole image, the square's centre and the left and right quarters of the gradient.
        assert_close(mean(&back, 0, 0, 1228, 768), mean(&src, 0, 0, 1440, 900), 2.0, "whole image");
        assert_close(mean(&back, 574, 344, 654, 424), [220.0, 30.0, 30.0], 6.0, "square");
        assert_close(mean(&back, 0, 0, 200, 768), mean(&src, 0, 0, 234, 900), 3.0, "left");
        assert_close(mean(&back, 1028, 0, 1228, 768), mean(&src, 1206, 0, 1440, 900), 3.0, "right");
    }

    #[test]
    fn png_in_jpeg_out() {
        let src = gradient_with_square(1920, 1080);
        let mut png = Vec::new();
        src.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).unwrap();
        let out = png_to_model_jpeg(&png, 80).unwrap();
        assert_eq!(&out.jpeg[..2], &[0xFF, 0xD8]);
        let back = image::load_from_memory(&out.jpeg).unwrap();
        assert_eq!((back.width(), back.height()), (1365, 768));
        assert!(png_to_model_jpeg(b"not a png", 80).is_err());
    }

    #[test]
    fn a_small_image_is_encoded_at_its_own_size() {
        let src = gradient_with_square(800, 600);
        let out = rgba_to_model_jpeg(&src, 90).unwrap();
        assert_eq!(out.size, ModelSize { width: 800, height: 600, scale: 1.0 });
        let back = image::load_from_memory(&out.jpeg).unwrap().to_rgba8();
        assert_eq!(back.dimensions(), (800, 600));
        assert_close(mean(&back, 0, 0, 800, 600), mean(&src, 0, 0, 800, 600), 2.0, "whole image");
    }

    #[test]
    fn rgb_and_rgba_resize_and_encode_alike() {
        let rgba = gradient_with_square(300, 200);
        let rgb: Vec<u8> = rgba.pixels().flat_map(|p| [p.0[0], p.0[1], p.0[2]]).collect();
        for filter in [Filter::Box, Filter::Bilinear, Filter::Bicubic] {
            let small_rgb = resize(&rgb, 300, 200, Layout::Rgb8, (150, 100), filter).unwrap();
            let small_rgba = resize_rgba(&rgba, 150, 100, filter).unwrap();
            assert_eq!(small_rgb.len(), 150 * 100 * 3);
            let dropped: Vec<u8> = small_rgba.pixels().flat_map(|p| [p.0[0], p.0[1], p.0[2]]).collect();
            assert_eq!(small_rgb, dropped, "{filter:?}");
            let a = encode_jpeg(&small_rgb, 150, 100, Layout::Rgb8, 75).unwrap();
            // Any alpha: it is not composited, only dropped.
            let mut translucent = small_rgba.clone();
            translucent.pixels_mut().enumerate().for_each(|(i, p)| p.0[3] = (i * 37 % 256) as u8);
            let b = encode_jpeg(translucent.as_raw(), 150, 100, Layout::Rgba8, 75).unwrap();
            // The bytes need not match (the encoder's RGB and RGBA paths may differ), the pictures do.
            let (a, b) =
                (image::load_from_memory(&a).unwrap().to_rgb8(), image::load_from_memory(&b).unwrap().to_rgb8());
            let worst = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(worst <= 1, "{filter:?}: RGB and RGBA differ by up to {worst}");
        }
    }

    #[test]
    fn transparent_pixels_do_not_bleed_when_resizing_rgba() {
        // Left half opaque blue, right half fully transparent "red".
        let src = RgbaImage::from_fn(64, 8, |x, _| if x < 32 { Rgba([0, 0, 255, 255]) } else { Rgba([255, 0, 0, 0]) });
        let small = resize_rgba(&src, 8, 1, Filter::Bicubic).unwrap();
        let edge = small.get_pixel(3, 0).0;
        assert!(edge[0] < 8 && edge[3] > 200, "{edge:?}");
    }

    #[test]
    fn bad_buffers_and_sizes_are_errors() {
        let px = vec![0u8; 10 * 10 * 3];
        assert!(matches!(encode_jpeg(&px, 10, 10, Layout::Rgba8, 75), Err(FastImgError::BufferSize { .. })));
        assert!(matches!(encode_jpeg(&px, 0, 10, Layout::Rgb8, 75), Err(FastImgError::Empty { .. })));
        assert!(matches!(resize(&px, 10, 10, Layout::Rgb8, (0, 5), Filter::Box), Err(FastImgError::Empty { .. })));
        let wide = vec![0u8; 70_000 * 3];
        assert!(matches!(encode_jpeg(&wide, 70_000, 1, Layout::Rgb8, 75), Err(FastImgError::TooLargeForJpeg { .. })));
        // Quality is clamped rather than refused.
        assert!(encode_jpeg(&px, 10, 10, Layout::Rgb8, 0).is_ok());
        assert!(encode_jpeg(&px, 10, 10, Layout::Rgb8, 255).is_ok());
    }
}
