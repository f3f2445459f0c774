//! The choices of `ksrt bench`'s options that the harness itself reads: which sections run and
//! in which order the primary rays go.

/// A part of the default measurements (`--sections`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Section {
    /// BLAS build (fast-trace and fast-build), refit, skinned refit and SAH cost.
    Builds,
    /// Primary, AO and diffuse ray batches and the peer workload.
    Rays,
    /// The lighting cache.
    Cache,
    /// The SDK's trace tasks.
    Tasks,
    /// The TLAS table.
    Tlas,
}

impl Section {
    /// Whether `sections` (`--sections`; empty: all) includes this one.
    pub fn runs_in(self, sections: &[Section]) -> bool {
        sections.is_empty() || sections.contains(&self)
    }
}

/// Order of the bench's primary rays (`--ray-order`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RayOrder {
    /// Row by row over the image.
    #[default]
    Rows,
    /// 8×8-pixel tiles, row by row; inside a tile, row by row.
    Tiles,
}

impl RayOrder {
    /// The pixels of a `width × height` image in this order.
    pub fn pixels(self, (width, height): (u32, u32)) -> Vec<(u32, u32)> {
        match self {
            RayOrder::Rows => (0..height)
                .flat_map(|y| (0..width).map(move |x| (x, y)))
                .collect(),
            RayOrder::Tiles => {
                const T: u32 = 8;
                let tiles = (0..height.div_ceil(T))
                    .flat_map(|ty| (0..width.div_ceil(T)).map(move |tx| (tx, ty)));
                tiles
                    .flat_map(|(tx, ty)| {
                        (0..T).flat_map(move |y| (0..T).map(move |x| (tx * T + x, ty * T + y)))
                    })
                    .filter(|&(x, y)| x < width && y < height)
                    .collect()
            }
        }
    }
}
