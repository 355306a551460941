//! Drawing particle frames and saving them as PNG pictures or animated GIFs.
//!
//! [`render_frame`] draws the particles of one simulation step over the grid's obstacle cells
//! into an [`RgbImage`]; [`write_png`] saves one picture and [`GifWriter`] streams a sequence of
//! pictures into an animated GIF.
//!
//! Picture coordinates: physical axis 0 (x) runs to the right and axis 1 (y) runs up, so the
//! top row of the picture is the top of the domain. Three-dimensional frames are projected onto
//! the x-y plane.

use std::borrow::Cow;
use std::collections::HashMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::{OutputError, write_atomic};

/// The particle kind of obstacle and boundary particles, drawn dark grey by
/// [`FrameStyle::default`] (the thesis' convention: obstacles 0, liquid 1).
pub(crate) const KIND_OBSTACLE: u8 = 0;
/// The particle kind of liquid particles, drawn blue by [`FrameStyle::default`].
pub(crate) const KIND_LIQUID: u8 = 1;

/// The largest picture [`render_frame`] draws, in pixels (2^28, i.e. 768 MiB of RGB).
pub(crate) const MAX_PIXELS: u64 = 1 << 28;

/// An 8-bit RGB picture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` RGB triples, row by row from the top row, each row from left to right.
    pub pixels: Vec<u8>,
}

impl RgbImage {
    /// A picture filled with `color` (allocates `width * height * 3` bytes).
    pub fn new(width: u32, height: u32, color: [u8; 3]) -> Self {
        let n = width as usize * height as usize;
        RgbImage {
            width,
            height,
            pixels: color.repeat(n),
        }
    }

    /// The colour of the pixel in column `x` and row `y` (row 0 at the top), `None` outside.
    #[cfg(test)]
    pub(crate) fn pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        let i = self.index(x, y)?;
        let p = self.pixels.get(i..i + 3)?;
        Some([p[0], p[1], p[2]])
    }

    /// Sets the pixel in column `x` and row `y`; does nothing outside the picture.
    pub(crate) fn set_pixel(&mut self, x: u32, y: u32, color: [u8; 3]) {
        if let Some(i) = self.index(x, y)
            && let Some(p) = self.pixels.get_mut(i..i + 3)
        {
            p.copy_from_slice(&color);
        }
    }

    fn index(&self, x: u32, y: u32) -> Option<usize> {
        (x < self.width && y < self.height)
            .then(|| (y as usize * self.width as usize + x as usize) * 3)
    }

    /// Checks that `pixels` holds `width * height` RGB triples.
    pub fn validate(&self) -> Result<(), OutputError> {
        let expected = u128::from(self.width) * u128::from(self.height) * 3;
        if self.pixels.len() as u128 == expected {
            Ok(())
        } else {
            Err(OutputError::InvalidInput(format!(
                "a {}x{} RGB picture needs {expected} bytes, not {}",
                self.width,
                self.height,
                self.pixels.len()
            )))
        }
    }

    /// Fills the rectangle of columns `x0..x1` and rows `y0..y1`, clipped to the picture.
    fn fill_rect(&mut self, x0: u32, y0: u32, x1: u32, y1: u32, color: [u8; 3]) {
        let (x1, y1) = (x1.min(self.width), y1.min(self.height));
        for y in y0..y1 {
            for x in x0..x1 {
                self.set_pixel(x, y, color);
            }
        }
    }
}

/// Pictures of the same height placed left to right, `gap` columns of `gap_color` between
/// neighbours (a rollout's truth beside its prediction).
///
/// Fails with [`OutputError::InvalidInput`] when there is no picture, the heights differ or a
/// picture's pixels do not fill its size.
pub(crate) fn side_by_side(
    images: &[&RgbImage],
    gap: u32,
    gap_color: [u8; 3],
) -> Result<RgbImage, OutputError> {
    let Some(first) = images.first() else {
        return Err(OutputError::InvalidInput(
            "side_by_side: no pictures".into(),
        ));
    };
    let height = first.height;
    let mut width = 0u32;
    for (i, image) in images.iter().enumerate() {
        image.validate()?;
        if image.height != height {
            return Err(OutputError::InvalidInput(format!(
                "side_by_side: picture {i} is {} pixels high, picture 0 {height}",
                image.height
            )));
        }
        let gap = if i == 0 { 0 } else { gap };
        width = width
            .checked_add(gap)
            .and_then(|w| w.checked_add(image.width))
            .ok_or_else(|| OutputError::InvalidInput("side_by_side: too wide".into()))?;
    }
    if u64::from(width) * u64::from(height) > MAX_PIXELS {
        return Err(OutputError::InvalidInput(format!(
            "side_by_side: a {width}x{height} picture is too large"
        )));
    }
    let mut out = RgbImage::new(width, height, gap_color);
    let row_bytes = width as usize * 3;
    let mut x0 = 0usize;
    for (i, image) in images.iter().enumerate() {
        if i > 0 {
            x0 += gap as usize;
        }
        let w = image.width as usize * 3;
        for y in 0..height as usize {
            let dst = y * row_bytes + x0 * 3;
            out.pixels[dst..dst + w].copy_from_slice(&image.pixels[y * w..(y + 1) * w]);
        }
        x0 += image.width as usize;
    }
    Ok(out)
}

/// How [`render_frame`] draws a frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FrameStyle {
    /// The size of one grid cell in pixels (cells are drawn square).
    pub pixels_per_cell: u32,
    /// The radius of the particle discs, in cells.
    pub particle_radius: f32,
    /// The colour of empty space.
    pub background: [u8; 3],
    /// The colour of obstacle (solid) grid cells.
    pub obstacle_cell_color: [u8; 3],
    /// The colour of the frame drawn around the domain.
    pub frame_color: [u8; 3],
    /// The width of that frame in pixels, outside the domain (0: no frame).
    pub frame_width: u32,
    /// The colour of each particle kind: particles of kind `k` are drawn in `kind_colors[k]`.
    pub kind_colors: Vec<[u8; 3]>,
    /// The colour of particles whose kind has no entry in `kind_colors`.
    pub other_kind_color: [u8; 3],
    /// In 3D, draw far particles (small z) paler, in [`DEPTH_LEVELS`] steps, and near particles
    /// over far ones.
    pub depth_shading: bool,
}

/// The number of shades used for depth shading in 3D (see [`FrameStyle::depth_shading`]).
pub(crate) const DEPTH_LEVELS: u32 = 4;

impl Default for FrameStyle {
    /// 8 pixels per cell, discs of 0.35 cells, white background, light grey obstacle cells, a
    /// one-pixel dark frame; kinds: [`KIND_LIQUID`] blue, [`KIND_OBSTACLE`] dark grey, then
    /// orange, green, red, purple, teal and brown; others magenta.
    fn default() -> Self {
        FrameStyle {
            pixels_per_cell: 8,
            particle_radius: 0.35,
            background: [255, 255, 255],
            obstacle_cell_color: [200, 200, 200],
            frame_color: [40, 40, 40],
            frame_width: 1,
            kind_colors: vec![
                [80, 80, 80],   // obstacle / boundary
                [30, 100, 220], // liquid
                [240, 140, 20],
                [40, 160, 60],
                [210, 40, 40],
                [140, 70, 190],
                [0, 150, 150],
                [140, 90, 40],
            ],
            other_kind_color: [220, 0, 170],
            depth_shading: true,
        }
    }
}

impl FrameStyle {
    /// The colour of particles of kind `kind`.
    pub(crate) fn kind_color(&self, kind: u8) -> [u8; 3] {
        self.kind_colors
            .get(usize::from(kind))
            .copied()
            .unwrap_or(self.other_kind_color)
    }

    /// Every colour [`render_frame`] can draw with this style (depth shades included), followed
    /// by a few greys, without duplicates and at most 256: a palette for [`GifWriter`].
    pub(crate) fn palette(&self) -> Vec<[u8; 3]> {
        let mut colors = vec![self.background, self.obstacle_cell_color, self.frame_color];
        let kinds = self
            .kind_colors
            .iter()
            .chain(std::iter::once(&self.other_kind_color));
        for &c in kinds {
            colors.push(c);
            if self.depth_shading {
                colors.extend((1..DEPTH_LEVELS).map(|level| shade(c, self.background, level)));
            }
        }
        colors.extend([
            [0, 0, 0],
            [64, 64, 64],
            [128, 128, 128],
            [192, 192, 192],
            [255; 3],
        ]);
        let mut unique = Vec::with_capacity(colors.len());
        for c in colors {
            if !unique.contains(&c) {
                unique.push(c);
            }
        }
        unique.truncate(256);
        unique
    }
}

/// `color` faded towards `background` by `level` steps of [`DEPTH_LEVELS`] (0: unchanged).
fn shade(color: [u8; 3], background: [u8; 3], level: u32) -> [u8; 3] {
    // At most 60% of the way to the background, so that far particles stay visible.
    let t = 0.6 * level as f32 / DEPTH_LEVELS as f32;
    let mix = |c: u8, b: u8| (f32::from(c) + (f32::from(b) - f32::from(c)) * t).round() as u8;
    [
        mix(color[0], background[0]),
        mix(color[1], background[1]),
        mix(color[2], background[2]),
    ]
}

/// Draws one frame of particles.
///
/// - `positions`: `n * dim` coordinates, particle after particle; `dim` is 2 or 3. In 3D the
///   particles are projected onto the x-y plane (axis 2 is the depth, see
///   [`FrameStyle::depth_shading`]).
/// - `kinds`: `n` particle kinds, choosing the colour ([`FrameStyle::kind_colors`]).
/// - `domain_lower`, `domain_upper`: the domain's corners (`dim` values each).
/// - `resolution`: the grid's cells per axis (`dim` values); the picture is
///   `resolution[0] * pixels_per_cell` by `resolution[1] * pixels_per_cell` pixels plus the frame.
/// - `obstacle_cells`: optional solid flags of the grid cells, row-major over `resolution`
///   (2D: cell `(i, j)` at `i * ny + j`, `i` along x; 3D: `(i * ny + j) * nz + k`). In 3D a
///   column is drawn solid when any of its cells is.
///
/// Axis 0 runs to the right and axis 1 upwards. Particles are discs of
/// [`FrameStyle::particle_radius`] cells (at least one pixel), clipped to the domain; particles
/// with non-finite coordinates are skipped.
///
/// Fails with [`OutputError::InvalidInput`] when the lengths disagree, `dim` is not 2 or 3, the
/// domain is empty or not finite, or the picture would exceed 2^28 pixels.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_frame(
    positions: &[f32],
    dim: usize,
    kinds: &[u8],
    domain_lower: &[f32],
    domain_upper: &[f32],
    resolution: &[usize],
    obstacle_cells: Option<&[bool]>,
    style: &FrameStyle,
) -> Result<RgbImage, OutputError> {
    let layout = FrameLayout::check(
        positions.len(),
        dim,
        kinds.len(),
        domain_lower,
        domain_upper,
        resolution,
        obstacle_cells.map(<[bool]>::len),
        style,
    )?;
    let FrameLayout {
        width,
        height,
        frame,
        inner_w,
        inner_h,
    } = layout;
    let mut image = RgbImage::new(width, height, style.background);
    image.fill_rect(0, 0, width, height, style.frame_color);
    image.fill_rect(
        frame,
        frame,
        frame + inner_w,
        frame + inner_h,
        style.background,
    );
    if let Some(obstacles) = obstacle_cells {
        draw_obstacle_cells(&mut image, obstacles, resolution, frame, style);
    }

    // Far particles first, so that near ones are drawn over them.
    let n = kinds.len();
    let mut order: Vec<usize> = (0..n).collect();
    if dim == 3 {
        order.sort_by(|&a, &b| positions[a * 3 + 2].total_cmp(&positions[b * 3 + 2]));
    }
    let scale_x = inner_w as f32 / (domain_upper[0] - domain_lower[0]);
    let scale_y = inner_h as f32 / (domain_upper[1] - domain_lower[1]);
    let radius = (style.particle_radius * style.pixels_per_cell as f32).max(0.5);
    let clip = [
        frame as f32,
        (frame + inner_w) as f32,
        frame as f32,
        (frame + inner_h) as f32,
    ];
    for p in order {
        let x = &positions[p * dim..(p + 1) * dim];
        if x.iter().any(|c| !c.is_finite()) {
            continue;
        }
        let mut color = style.kind_color(kinds[p]);
        if dim == 3 && style.depth_shading {
            let depth = (domain_upper[2] - x[2]) / (domain_upper[2] - domain_lower[2]);
            let level = (depth.clamp(0.0, 1.0) * DEPTH_LEVELS as f32) as u32;
            color = shade(color, style.background, level.min(DEPTH_LEVELS - 1));
        }
        let cx = frame as f32 + (x[0] - domain_lower[0]) * scale_x;
        let cy = frame as f32 + (domain_upper[1] - x[1]) * scale_y;
        draw_disc(&mut image, [cx, cy], radius, clip, color);
    }
    Ok(image)
}

/// The size of a frame's picture: `width × height` pixels, the domain's `inner_w × inner_h`
/// inside a border of `frame` pixels.
#[derive(Debug, Clone, Copy)]
struct FrameLayout {
    width: u32,
    height: u32,
    frame: u32,
    inner_w: u32,
    inner_h: u32,
}

impl FrameLayout {
    /// The layout of [`render_frame`]'s picture, after checking its input (`coordinates`
    /// values, `kinds` particles, `obstacle_flags` cells when given).
    #[allow(clippy::too_many_arguments)]
    fn check(
        coordinates: usize,
        dim: usize,
        kinds: usize,
        domain_lower: &[f32],
        domain_upper: &[f32],
        resolution: &[usize],
        obstacle_flags: Option<usize>,
        style: &FrameStyle,
    ) -> Result<Self, OutputError> {
        let bad = |msg: String| Err(OutputError::InvalidInput(format!("render_frame: {msg}")));
        if dim != 2 && dim != 3 {
            return bad(format!("dim must be 2 or 3, not {dim}"));
        }
        if !coordinates.is_multiple_of(dim) {
            return bad(format!(
                "{coordinates} coordinates are not a multiple of dim {dim}"
            ));
        }
        let n = coordinates / dim;
        if kinds != n {
            return bad(format!("{kinds} kinds for {n} particles"));
        }
        if domain_lower.len() != dim || domain_upper.len() != dim || resolution.len() != dim {
            return bad(format!(
                "domain corners ({} and {} values) and resolution ({} values) need dim = {dim} values",
                domain_lower.len(),
                domain_upper.len(),
                resolution.len()
            ));
        }
        for axis in 0..dim {
            let (lo, hi) = (domain_lower[axis], domain_upper[axis]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(format!(
                    "empty or non-finite domain [{lo}, {hi}] on axis {axis}"
                ));
            }
            if resolution[axis] == 0 {
                return bad(format!("resolution is 0 on axis {axis}"));
            }
        }
        let cells: Option<usize> = resolution.iter().try_fold(1usize, |a, &r| a.checked_mul(r));
        if let Some(flags) = obstacle_flags
            && Some(flags) != cells
        {
            return bad(format!(
                "{flags} obstacle flags for a grid of {resolution:?} cells"
            ));
        }
        if style.pixels_per_cell == 0 {
            return bad("pixels_per_cell is 0".into());
        }
        let ppc = u64::from(style.pixels_per_cell);
        let frame = u64::from(style.frame_width);
        let inner_w = resolution[0] as u64 * ppc;
        let inner_h = resolution[1] as u64 * ppc;
        let width = inner_w + 2 * frame;
        let height = inner_h + 2 * frame;
        if width.saturating_mul(height) > MAX_PIXELS {
            return bad(format!("a {width}x{height} picture is too large"));
        }
        // All fit in u32 since width times height is at most 2^28.
        Ok(FrameLayout {
            width: width as u32,
            height: height as u32,
            frame: frame as u32,
            inner_w: inner_w as u32,
            inner_h: inner_h as u32,
        })
    }
}

/// Fills the cells of the `resolution` grid whose column (in 3D: any cell along z) holds an
/// obstacle; row 0 is the bottom of the domain.
fn draw_obstacle_cells(
    image: &mut RgbImage,
    obstacles: &[bool],
    resolution: &[usize],
    frame: u32,
    style: &FrameStyle,
) {
    let (nx, ny) = (resolution[0], resolution[1]);
    let nz = resolution.get(2).copied().unwrap_or(1);
    let ppc = style.pixels_per_cell;
    for i in 0..nx {
        for j in 0..ny {
            let column = (i * ny + j) * nz;
            if obstacles[column..column + nz].iter().any(|&s| s) {
                let x0 = frame + i as u32 * ppc;
                let y0 = frame + (ny - 1 - j) as u32 * ppc;
                image.fill_rect(x0, y0, x0 + ppc, y0 + ppc, style.obstacle_cell_color);
            }
        }
    }
}

/// Draws the pixels whose centres lie in the disc of `radius` around `centre`, clipped to
/// `[x_min, x_max, y_min, y_max]`; however small the disc, the pixel under its centre is drawn.
fn draw_disc(image: &mut RgbImage, centre: [f32; 2], radius: f32, clip: [f32; 4], color: [u8; 3]) {
    let [cx, cy] = centre;
    let [px_min, px_max, py_min, py_max] = clip;
    let x0 = (cx - radius).floor().max(px_min);
    let x1 = (cx + radius).ceil().min(px_max);
    let y0 = (cy - radius).floor().max(py_min);
    let y1 = (cy + radius).ceil().min(py_max);
    let mut py = y0;
    while py < y1 {
        let mut px = x0;
        while px < x1 {
            let (dx, dy) = (px + 0.5 - cx, py + 0.5 - cy);
            if dx * dx + dy * dy <= radius * radius {
                image.set_pixel(px as u32, py as u32, color);
            }
            px += 1.0;
        }
        py += 1.0;
    }
    if (px_min..px_max).contains(&cx) && (py_min..py_max).contains(&cy) {
        image.set_pixel(cx as u32, cy as u32, color);
    }
}

/// Saves `image` as an 8-bit RGB PNG file, atomically (temporary file, sync, rename).
pub fn write_png(path: impl AsRef<Path>, image: &RgbImage) -> Result<(), OutputError> {
    let path = path.as_ref();
    image.validate()?;
    let png_error = |source| OutputError::Png {
        path: path.to_path_buf(),
        source,
    };
    write_atomic(path, |w| {
        let mut encoder = png::Encoder::new(w, image.width, image.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(png_error)?;
        writer.write_image_data(&image.pixels).map_err(png_error)?;
        writer.finish().map_err(png_error)
    })
}

/// Writes an animated GIF frame by frame, looping forever.
///
/// Frames are quantised to a fixed palette (by default [`FrameStyle::palette`] of the default
/// style: the colours [`render_frame`] uses plus a few greys; other colours map to the nearest
/// palette entry). Each frame is written and flushed to the file as soon as it is added, so a
/// process killed mid-run leaves a GIF holding the frames so far, which viewers open (decoders
/// tolerate the missing trailer); [`GifWriter::finish`] writes the trailer and syncs the file.
/// Unlike [`write_png`], the file is therefore written in place, not atomically.
///
/// Dropping a `GifWriter` without calling `finish` leaves the file as a killed process would.
pub(crate) struct GifWriter {
    path: PathBuf,
    file: File,
    /// Encodes into memory; its bytes are moved to `file` after each step. `None` once finished.
    encoder: Option<gif::Encoder<Vec<u8>>>,
    width: u16,
    height: u16,
    delay_cs: u16,
    palette: Vec<[u8; 3]>,
    /// Palette index of each colour seen so far.
    lookup: HashMap<[u8; 3], u8>,
    indices: Vec<u8>,
    frames: usize,
}

impl std::fmt::Debug for GifWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter")
            .field("path", &self.path)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("delay_cs", &self.delay_cs)
            .field("frames", &self.frames)
            .finish_non_exhaustive()
    }
}

impl GifWriter {
    /// Creates (or truncates) the GIF file `path` for frames of `width` x `height` pixels shown
    /// `frame_delay_cs` hundredths of a second each, with the palette of
    /// [`FrameStyle::default`].
    pub(crate) fn create(
        path: impl AsRef<Path>,
        width: u32,
        height: u32,
        frame_delay_cs: u16,
    ) -> Result<Self, OutputError> {
        Self::create_with_palette(
            path,
            width,
            height,
            frame_delay_cs,
            &FrameStyle::default().palette(),
        )
    }

    /// As [`GifWriter::create`], with the given palette (1 to 256 colours; pass
    /// [`FrameStyle::palette`] of a custom style).
    pub(crate) fn create_with_palette(
        path: impl AsRef<Path>,
        width: u32,
        height: u32,
        frame_delay_cs: u16,
        palette: &[[u8; 3]],
    ) -> Result<Self, OutputError> {
        let path = path.as_ref().to_path_buf();
        let (Ok(w16), Ok(h16)) = (u16::try_from(width), u16::try_from(height)) else {
            return Err(OutputError::InvalidInput(format!(
                "'{}': a GIF is at most 65535x65535 pixels, not {width}x{height}",
                path.display()
            )));
        };
        if width == 0 || height == 0 {
            return Err(OutputError::InvalidInput(format!(
                "'{}': a GIF needs at least one pixel, not {width}x{height}",
                path.display()
            )));
        }
        if palette.is_empty() || palette.len() > 256 {
            return Err(OutputError::InvalidInput(format!(
                "'{}': a GIF palette has 1 to 256 colours, not {}",
                path.display(),
                palette.len()
            )));
        }
        let flat: Vec<u8> = palette.iter().flatten().copied().collect();
        let gif_error = |source| OutputError::Gif {
            path: path.clone(),
            source,
        };
        let mut encoder = gif::Encoder::new(Vec::new(), w16, h16, &flat).map_err(gif_error)?;
        encoder
            .set_repeat(gif::Repeat::Infinite)
            .map_err(gif_error)?;
        let file = File::create(&path).map_err(|e| OutputError::io(&path, "cannot create", e))?;
        let lookup = palette
            .iter()
            .enumerate()
            .rev() // The first of duplicate colours wins.
            .map(|(i, &c)| (c, i as u8))
            .collect();
        let mut writer = GifWriter {
            path,
            file,
            encoder: Some(encoder),
            width: w16,
            height: h16,
            delay_cs: frame_delay_cs,
            palette: palette.to_vec(),
            lookup,
            indices: Vec::new(),
            frames: 0,
        };
        writer.flush_encoded()?;
        Ok(writer)
    }

    /// Moves what the encoder produced so far to the file and flushes it.
    fn flush_encoded(&mut self) -> Result<(), OutputError> {
        let Some(encoder) = self.encoder.as_mut() else {
            return Ok(());
        };
        let bytes = encoder.get_mut();
        let result = self.file.write_all(bytes).and_then(|()| self.file.flush());
        bytes.clear();
        result.map_err(|e| OutputError::io(&self.path, "cannot write", e))
    }

    /// The palette index nearest to `color`.
    fn index_of(&mut self, color: [u8; 3]) -> u8 {
        if let Some(&i) = self.lookup.get(&color) {
            return i;
        }
        let distance = |c: &[u8; 3]| {
            (0..3)
                .map(|k| {
                    let d = i32::from(c[k]) - i32::from(color[k]);
                    d * d
                })
                .sum::<i32>()
        };
        let nearest = self
            .palette
            .iter()
            .enumerate()
            .min_by_key(|(_, c)| distance(c))
            .map_or(0, |(i, _)| i as u8);
        self.lookup.insert(color, nearest);
        nearest
    }

    /// Appends `image` as the next frame and flushes it to the file.
    ///
    /// Fails if the picture's size differs from the GIF's, if `finish` failed earlier, or on
    /// I/O errors.
    /// The number of frames written so far.
    #[cfg(test)]
    pub(crate) fn frames_written(&self) -> usize {
        self.frames
    }

    pub(crate) fn add_frame(&mut self, image: &RgbImage) -> Result<(), OutputError> {
        image.validate()?;
        if image.width != u32::from(self.width) || image.height != u32::from(self.height) {
            return Err(OutputError::InvalidInput(format!(
                "'{}': a {}x{} frame does not fit the {}x{} GIF",
                self.path.display(),
                image.width,
                image.height,
                self.width,
                self.height
            )));
        }
        let mut indices = std::mem::take(&mut self.indices);
        indices.clear();
        indices.reserve(image.pixels.len() / 3);
        let mut last: Option<([u8; 3], u8)> = None;
        for p in image.pixels.chunks_exact(3) {
            let color = [p[0], p[1], p[2]];
            let index = match last {
                Some((c, i)) if c == color => i,
                _ => {
                    let i = self.index_of(color);
                    last = Some((color, i));
                    i
                }
            };
            indices.push(index);
        }
        let frame = gif::Frame {
            width: self.width,
            height: self.height,
            delay: self.delay_cs,
            buffer: Cow::Borrowed(&indices),
            ..gif::Frame::default()
        };
        let result = match self.encoder.as_mut() {
            Some(encoder) => encoder
                .write_frame(&frame)
                .map_err(|source| OutputError::Gif {
                    path: self.path.clone(),
                    source,
                }),
            None => Err(OutputError::InvalidInput(format!(
                "'{}': the GIF is already finished",
                self.path.display()
            ))),
        };
        self.indices = indices;
        result?;
        self.flush_encoded()?;
        self.frames += 1;
        Ok(())
    }

    /// Writes the GIF trailer and syncs the file to disk.
    pub fn finish(mut self) -> Result<(), OutputError> {
        let Some(encoder) = self.encoder.take() else {
            return Ok(());
        };
        let tail = encoder.into_inner().map_err(|source| OutputError::Gif {
            path: self.path.clone(),
            source,
        })?;
        self.file
            .write_all(&tail)
            .and_then(|()| self.file.sync_all())
            .map_err(|e| OutputError::io(&self.path, "cannot write", e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::test_util::temp_dir;

    const WHITE: [u8; 3] = [255, 255, 255];

    /// A 4x4-cell domain [0, 4]^2, 10 pixels per cell, 1-pixel frame: 42x42 pixels; the cell
    /// (i, j) covers columns 1 + 10 i .. 11 + 10 i and rows 1 + 10 (3 - j) .. 11 + 10 (3 - j).
    fn style() -> FrameStyle {
        FrameStyle {
            pixels_per_cell: 10,
            ..FrameStyle::default()
        }
    }

    fn render_2d(positions: &[f32], kinds: &[u8], obstacles: Option<&[bool]>) -> RgbImage {
        render_frame(
            positions,
            2,
            kinds,
            &[0.0, 0.0],
            &[4.0, 4.0],
            &[4, 4],
            obstacles,
            &style(),
        )
        .unwrap()
    }

    #[test]
    fn side_by_side_places_pictures_left_to_right() {
        let red = RgbImage::new(2, 3, [255, 0, 0]);
        let blue = RgbImage::new(4, 3, [0, 0, 255]);
        let both = side_by_side(&[&red, &blue], 1, WHITE).unwrap();
        assert_eq!((both.width, both.height), (7, 3));
        for y in 0..3 {
            assert_eq!(both.pixel(1, y), Some([255, 0, 0]));
            assert_eq!(both.pixel(2, y), Some(WHITE));
            assert_eq!(both.pixel(3, y), Some([0, 0, 255]));
            assert_eq!(both.pixel(6, y), Some([0, 0, 255]));
        }
        let short = RgbImage::new(2, 2, WHITE);
        assert!(side_by_side(&[&red, &short], 1, WHITE).is_err());
        assert!(side_by_side(&[], 1, WHITE).is_err());
    }

    #[test]
    fn particle_lights_expected_pixel() {
        let s = style();
        let image = render_2d(&[0.55, 3.55], &[KIND_LIQUID], None);
        assert_eq!((image.width, image.height), (42, 42));
        // x: 1 + 0.55 * 10 = 6.5 -> column 6; y: 1 + (4 - 3.55) * 10 = 5.5 -> row 5.
        assert_eq!(image.pixel(6, 5), Some(s.kind_color(KIND_LIQUID)));
        // Radius 3.5 pixels: 3 pixels away is inside, 5 is outside.
        assert_eq!(image.pixel(9, 5), Some(s.kind_color(KIND_LIQUID)));
        assert_eq!(image.pixel(11, 5), Some(WHITE));
        assert_eq!(image.pixel(30, 30), Some(WHITE));
        // The frame.
        assert_eq!(image.pixel(0, 0), Some(s.frame_color));
        assert_eq!(image.pixel(41, 20), Some(s.frame_color));
        assert_eq!(image.pixel(20, 41), Some(s.frame_color));
        assert_eq!(image.pixel(1, 1), Some(WHITE));
    }

    #[test]
    fn y_axis_points_up() {
        let s = style();
        let image = render_2d(
            &[0.55, 0.45, 3.55, 0.45],
            &[KIND_LIQUID, KIND_OBSTACLE],
            None,
        );
        // y = 0.45 -> row 1 + 35.5 = 36: near the bottom.
        assert_eq!(image.pixel(6, 36), Some(s.kind_color(KIND_LIQUID)));
        assert_eq!(image.pixel(6, 5), Some(WHITE));
        // x = 3.55 -> column 36: to the right.
        assert_eq!(image.pixel(36, 36), Some(s.kind_color(KIND_OBSTACLE)));
        assert_ne!(s.kind_color(KIND_LIQUID), s.kind_color(KIND_OBSTACLE));
    }

    #[test]
    fn obstacle_cells_are_grey() {
        let s = style();
        let mut solid = vec![false; 16];
        solid[4] = true; // cell (i = 1, j = 0): columns 11..21, rows 31..41.
        let image = render_2d(&[], &[], Some(&solid));
        assert_eq!(image.pixel(11, 31), Some(s.obstacle_cell_color));
        assert_eq!(image.pixel(20, 40), Some(s.obstacle_cell_color));
        assert_eq!(image.pixel(15, 5), Some(WHITE));
        assert_eq!(image.pixel(5, 35), Some(WHITE));
        assert_eq!(image.pixel(21, 35), Some(WHITE));
        assert_eq!(image.pixel(15, 30), Some(WHITE));
    }

    #[test]
    fn three_d_projects_and_shades_by_depth() {
        let s = style();
        let render = |z: f32| {
            render_frame(
                &[0.55, 3.55, z],
                3,
                &[KIND_LIQUID],
                &[0.0; 3],
                &[4.0; 3],
                &[4, 4, 4],
                None,
                &s,
            )
            .unwrap()
        };
        let near = render(3.9).pixel(6, 5).unwrap();
        let far = render(0.1).pixel(6, 5).unwrap();
        assert_eq!(near, s.kind_color(KIND_LIQUID));
        assert_ne!(far, near);
        assert!(s.palette().contains(&far));
        // A near particle covers a far one at the same x-y.
        let both = render_frame(
            &[0.55, 3.55, 3.9, 0.55, 3.55, 0.1],
            3,
            &[KIND_LIQUID, KIND_OBSTACLE],
            &[0.0; 3],
            &[4.0; 3],
            &[4, 4, 4],
            Some(&[false; 64]),
            &s,
        )
        .unwrap();
        assert_eq!(both.pixel(6, 5), Some(s.kind_color(KIND_LIQUID)));
    }

    #[test]
    fn bad_input_is_an_error() {
        let s = style();
        let lo = [0.0, 0.0];
        let hi = [4.0, 4.0];
        let res = [4, 4];
        assert!(render_frame(&[0.0; 3], 2, &[0], &lo, &hi, &res, None, &s).is_err());
        assert!(render_frame(&[0.0; 2], 2, &[], &lo, &hi, &res, None, &s).is_err());
        assert!(render_frame(&[0.0; 4], 4, &[0], &lo, &hi, &res, None, &s).is_err());
        assert!(render_frame(&[], 2, &[], &hi, &lo, &res, None, &s).is_err());
        assert!(render_frame(&[], 2, &[], &lo, &hi, &[4, 0], None, &s).is_err());
        assert!(render_frame(&[], 2, &[], &lo, &hi, &res, Some(&[true; 3]), &s).is_err());
        assert!(render_frame(&[], 2, &[], &lo, &hi, &[1 << 20, 1 << 20], None, &s).is_err());
        // Non-finite and far-away particles are skipped or clipped, not errors.
        let image = render_frame(
            &[f32::NAN, 1.0, 1e30, -1e30, 4.0, 4.0],
            2,
            &[0, 0, 200],
            &lo,
            &hi,
            &res,
            None,
            &s,
        )
        .unwrap();
        assert_eq!(image.pixel(40, 1), Some(s.other_kind_color));
    }

    #[test]
    fn png_round_trip() {
        let dir = temp_dir("png");
        let path = dir.join("frame.png");
        let image = render_2d(&[1.0, 1.0, 2.5, 3.0], &[0, 1], Some(&[true; 16]));
        write_png(&path, &image).unwrap();
        let decoder = png::Decoder::new(std::io::BufReader::new(File::open(&path).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (42, 42));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(&buf[..info.buffer_size()], &image.pixels[..]);
        let bad = RgbImage {
            width: 2,
            height: 2,
            pixels: vec![0; 5],
        };
        assert!(write_png(dir.join("bad.png"), &bad).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Decodes the frames of a GIF until its end, or until the data runs out; returns their
    /// sizes and RGBA pixels.
    fn decode_gif(path: &Path) -> Vec<(u16, u16, Vec<u8>)> {
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(File::open(path).unwrap()).unwrap();
        assert_eq!(decoder.repeat(), gif::Repeat::Infinite);
        let mut frames = Vec::new();
        while let Ok(Some(frame)) = decoder.read_next_frame() {
            frames.push((frame.width, frame.height, frame.buffer.to_vec()));
        }
        frames
    }

    fn rgba_at(rgba: &[u8], width: u32, x: u32, y: u32) -> [u8; 3] {
        let i = ((y * width + x) * 4) as usize;
        [rgba[i], rgba[i + 1], rgba[i + 2]]
    }

    fn gif_frames(n: usize) -> Vec<RgbImage> {
        (0..n)
            .map(|k| render_2d(&[0.55 + k as f32, 3.55], &[KIND_LIQUID], None))
            .collect()
    }

    #[test]
    fn gif_with_three_frames_decodes() {
        let dir = temp_dir("gif");
        let path = dir.join("anim.gif");
        let images = gif_frames(3);
        let mut gif = GifWriter::create(&path, 42, 42, 5).unwrap();
        for image in &images {
            gif.add_frame(image).unwrap();
        }
        assert_eq!(gif.frames_written(), 3);
        assert!(gif.add_frame(&RgbImage::new(10, 10, WHITE)).is_err());
        gif.finish().unwrap();
        let frames = decode_gif(&path);
        assert_eq!(frames.len(), 3);
        let liquid = style().kind_color(KIND_LIQUID);
        for (k, (w, h, rgba)) in frames.iter().enumerate() {
            assert_eq!((*w, *h), (42, 42));
            // The palette holds the drawing's colours, so they survive exactly.
            assert_eq!(rgba_at(rgba, 42, 6 + 10 * k as u32, 5), liquid);
            assert_eq!(rgba_at(rgba, 42, 30, 30), WHITE);
            assert_eq!(rgba_at(rgba, 42, 0, 0), style().frame_color);
        }
        assert_eq!(std::fs::read(&path).unwrap().last(), Some(&0x3B));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn unfinished_gif_still_decodes() {
        let dir = temp_dir("gif-unfinished");
        let path = dir.join("killed.gif");
        let mut gif = GifWriter::create(&path, 42, 42, 5).unwrap();
        for image in &gif_frames(2) {
            gif.add_frame(image).unwrap();
        }
        // While the writer is alive the file already holds both frames.
        assert_eq!(decode_gif(&path).len(), 2);
        drop(gif);
        let bytes = std::fs::read(&path).unwrap();
        assert_ne!(bytes.last(), Some(&0x3B), "no trailer without finish");
        assert_eq!(decode_gif(&path).len(), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn gif_quantises_to_nearest_palette_colour() {
        let dir = temp_dir("gif-quantise");
        let path = dir.join("q.gif");
        let mut image = RgbImage::new(2, 1, [250, 250, 250]);
        image.set_pixel(1, 0, [35, 95, 215]);
        let mut gif = GifWriter::create(&path, 2, 1, 10).unwrap();
        gif.add_frame(&image).unwrap();
        gif.finish().unwrap();
        let frames = decode_gif(&path);
        assert_eq!(rgba_at(&frames[0].2, 2, 0, 0), WHITE);
        assert_eq!(
            rgba_at(&frames[0].2, 2, 1, 0),
            style().kind_color(KIND_LIQUID)
        );
        assert!(GifWriter::create(dir.join("big.gif"), 70_000, 1, 1).is_err());
        assert!(GifWriter::create_with_palette(dir.join("p.gif"), 1, 1, 1, &[]).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn default_palette_fits_a_gif() {
        let palette = FrameStyle::default().palette();
        assert!(palette.len() <= 256);
        let s = FrameStyle::default();
        for c in [
            s.background,
            s.obstacle_cell_color,
            s.frame_color,
            s.other_kind_color,
        ] {
            assert!(palette.contains(&c));
        }
        assert!(s.kind_colors.iter().all(|c| palette.contains(c)));
    }
}
