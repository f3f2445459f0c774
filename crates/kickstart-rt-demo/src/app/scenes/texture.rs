//! Decoding texture images from scene files, with the size bounded before anything is
//! allocated: a few bytes of header can claim an image of gigabytes.

use image::{ImageReader, Limits, RgbaImage};

/// The largest width or height the loaders decode: the largest 2D texture wgpu's default
/// limits guarantee, so every image loaded can be uploaded as it is.
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// The most memory one decode may allocate: an 8192 × 8192 image of 16-bit RGBA channels.
const MAX_DECODE_BYTES: u64 = 512 << 20;

/// Decodes a PNG, JPEG or EXR image to RGBA8, refusing one whose header claims a side above
/// [`MAX_TEXTURE_SIDE`] or whose decode would allocate more than 512 MiB.
pub fn decode_rgba8(bytes: &[u8]) -> Result<RgbaImage, String> {
    let reader = || {
        ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format!("cannot read the image: {e}"))
    };
    let (w, h) = reader()?.into_dimensions().map_err(decode_error)?;
    if w > MAX_TEXTURE_SIDE || h > MAX_TEXTURE_SIDE {
        return Err(format!(
            "the image is {w}×{h} pixels, too large: the largest side loaded is {MAX_TEXTURE_SIDE}"
        ));
    }
    let mut limits = Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    let mut reader = reader()?;
    reader.limits(limits);
    reader.decode().map(|i| i.to_rgba8()).map_err(decode_error)
}

/// A decoder's error as the loaders report it; a size past the decoder's limits says so.
fn decode_error(e: image::ImageError) -> String {
    match e {
        image::ImageError::Limits(_) => format!("the image is too large to decode ({e})"),
        _ => format!("cannot decode the image: {e}"),
    }
}

/// Rewrites the size a PNG's header claims (its pixels stay as they are), with the header's
/// checksum updated so that a decoder reads the claim: IHDR's width and height are bytes
/// 16..24, after the 8-byte signature, the chunk's length and type; its CRC-32 (of the type and
/// the 13 data bytes, 12..29) follows at 29..33.
#[cfg(test)]
pub fn claim_png_size(png: &mut [u8], w: u32, h: u32) {
    png[16..20].copy_from_slice(&w.to_be_bytes());
    png[20..24].copy_from_slice(&h.to_be_bytes());
    let mut crc = !0u32;
    for &byte in &png[12..29] {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    png[29..33].copy_from_slice(&(!crc).to_be_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid PNG of `w` × `h` pixels, then its header rewritten to claim `claim_w` × `claim_h`.
    fn png_claiming(w: u32, h: u32, claim_w: u32, claim_h: u32) -> Vec<u8> {
        let mut bytes = Vec::new();
        RgbaImage::from_pixel(w, h, image::Rgba([10, 20, 30, 255]))
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .map_err(|e| e.to_string())
            .unwrap_or_else(|e| panic!("encoding a test PNG: {e}"));
        claim_png_size(&mut bytes, claim_w, claim_h);
        bytes
    }

    #[test]
    fn a_rewritten_header_keeps_a_valid_checksum() {
        // The same size rewritten leaves the file exactly as the encoder wrote it.
        let mut png = png_claiming(3, 2, 3, 2);
        let original = png.clone();
        claim_png_size(&mut png, 3, 2);
        assert_eq!(png, original);
    }

    #[test]
    fn a_valid_image_decodes_to_its_pixels() {
        let png = png_claiming(3, 2, 3, 2);
        let img = decode_rgba8(&png).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.get_pixel(2, 1).0, [10, 20, 30, 255]);
    }

    #[test]
    fn a_header_claiming_a_huge_image_is_refused_before_decoding() {
        for (w, h) in [(8193, 4), (4, 100_000), (u32::MAX >> 1, u32::MAX >> 1)] {
            let e = decode_rgba8(&png_claiming(4, 4, w, h)).unwrap_err();
            assert!(e.contains("too large"), "{w}×{h}: {e}");
        }
    }
}
