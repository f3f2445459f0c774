//! `ksrt compare`: the PSNR of every PNG image two `ksrt render` output folders both hold (8-bit
//! levels, peak 255, over RGB), to check that a change leaves the images as they were.

use std::path::{Path, PathBuf};

use kickstart_rt_renderer::error::AnyResult;

use crate::lab::quality::metrics::{psnr, Srgb8};

/// One image of both folders and its PSNR (`f64::INFINITY`: identical).
#[derive(Debug, Clone, PartialEq)]
pub struct Compared {
    /// File name.
    pub name: String,
    /// PSNR of the first folder's image against the second's, dB.
    pub psnr: f64,
}

/// The PSNR of every `.png` both `a` and `b` hold, by name.
pub fn compare_folders(a: &Path, b: &Path) -> AnyResult<Vec<Compared>> {
    let mut names: Vec<String> = pngs(a)?
        .into_iter()
        .filter(|n| b.join(n).is_file())
        .collect();
    names.sort();
    if names.is_empty() {
        return Err(format!(
            "compare: no PNG image is in both {} and {}",
            a.display(),
            b.display()
        )
        .into());
    }
    names
        .into_iter()
        .map(|name| {
            let (ia, ib) = (load(&a.join(&name))?, load(&b.join(&name))?);
            let psnr = psnr(&ia, &ib).map_err(|e| format!("compare {name}: {e}"))?;
            Ok(Compared { name, psnr })
        })
        .collect()
}

/// Names of the `.png` files in `dir`.
fn pngs(dir: &Path) -> AnyResult<Vec<String>> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("compare: {}: {e}", dir.display()))?;
    let mut names = Vec::new();
    for entry in entries {
        let path: PathBuf = entry
            .map_err(|e| format!("compare: {}: {e}", dir.display()))?
            .path();
        if path.extension().is_some_and(|x| x == "png") {
            if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
                names.push(name.to_string());
            }
        }
    }
    Ok(names)
}

fn load(path: &Path) -> AnyResult<Srgb8> {
    let img = image::open(path)
        .map_err(|e| format!("compare: {}: {e}", path.display()))?
        .to_rgb8();
    Ok(Srgb8 {
        width: img.width(),
        height: img.height(),
        pixels: img.pixels().map(|p| p.0).collect(),
    })
}

/// Runs `ksrt compare A B --min-db D`: prints each image's PSNR and fails when one is below
/// `min_db`.
pub fn command(a: &Path, b: &Path, min_db: f64) -> AnyResult<()> {
    let rows = compare_folders(a, b)?;
    let mut low = Vec::new();
    for r in &rows {
        let shown = if r.psnr.is_infinite() {
            "identical".to_string()
        } else {
            format!("{:.2} dB", r.psnr)
        };
        println!("  {:<28} {shown}", r.name);
        if r.psnr < min_db {
            low.push(r.name.clone());
        }
    }
    if low.is_empty() {
        println!("{} images, each at least {min_db} dB", rows.len());
        Ok(())
    } else {
        Err(format!("compare: below {min_db} dB: {}", low.join(", ")).into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, level: u8) {
        let img = image::RgbImage::from_fn(8, 4, |x, _| image::Rgb([level, x as u8 * 10, 0]));
        img.save(dir.join(name)).unwrap();
    }

    #[test]
    fn identical_images_are_infinite_and_a_changed_one_fails_the_threshold() {
        let root = std::env::temp_dir().join(format!("ksrt-compare-{}", std::process::id()));
        let (a, b) = (root.join("a"), root.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        write(&a, "same.png", 100);
        write(&b, "same.png", 100);
        write(&a, "moved.png", 100);
        write(&b, "moved.png", 110);
        write(&a, "only-a.png", 1);
        let rows = compare_folders(&a, &b).unwrap();
        assert_eq!(rows.len(), 2, "{rows:?}");
        assert_eq!(rows[1].name, "same.png");
        assert!(rows[1].psnr.is_infinite());
        // One channel of every pixel off by 10: MSE 100 / 3.
        let expected = 10.0 * (255.0f64 * 255.0 / (100.0 / 3.0)).log10();
        assert!((rows[0].psnr - expected).abs() < 1e-9, "{rows:?}");
        let e = command(&a, &b, 40.0).unwrap_err().to_string();
        assert!(e.contains("moved.png") && !e.contains("same.png"), "{e}");
        assert!(command(&a, &b, 30.0).is_ok());
        let empty = root.join("empty");
        std::fs::create_dir_all(&empty).unwrap();
        assert!(compare_folders(&a, &empty).is_err());
        std::fs::remove_dir_all(&root).unwrap();
    }
}
