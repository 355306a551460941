//! Figures of several panels in a grid, written as one image.

use std::path::Path;

use plotters::prelude::Text;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::bitmap::{Bitmap, check_size, render_with};
use crate::chart::Area;
use crate::error::{draw_error, plot_name};
use crate::style::{Metrics, SUPERSAMPLE};
use crate::{BarChart, LinePlot, PlotError};

/// One panel of a [`Figure`].
#[derive(Debug, Clone, PartialEq)]
pub enum Panel {
    /// A line plot.
    Line(LinePlot),
    /// A bar chart.
    Bar(BarChart),
}

impl From<LinePlot> for Panel {
    fn from(plot: LinePlot) -> Panel {
        Panel::Line(plot)
    }
}

impl From<BarChart> for Panel {
    fn from(chart: BarChart) -> Panel {
        Panel::Bar(chart)
    }
}

impl Panel {
    fn size(&self) -> (u32, u32) {
        match self {
            Panel::Line(plot) => plot.size,
            Panel::Bar(chart) => chart.size,
        }
    }

    fn title(&self) -> &str {
        match self {
            Panel::Line(plot) => &plot.title,
            Panel::Bar(chart) => &chart.title,
        }
    }

    fn draw_on(&self, area: &Area<'_>) -> Result<(), PlotError> {
        match self {
            Panel::Line(plot) => plot.draw_on(area).map(drop),
            Panel::Bar(chart) => chart.draw_on(area).map(drop),
        }
    }
}

/// Panels in a grid of `columns` columns, filled row by row, under an optional common title.
///
/// Every cell is as large as the largest panel's `size`; each panel is drawn filling its cell,
/// with its own axes, title and legend. The image is `columns` cells wide and as many rows high
/// as the panels need, plus a strip for the title.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// The title above all panels; empty for none.
    pub title: String,
    /// The panels, row by row.
    pub panels: Vec<Panel>,
    /// Panels per row, at least 1.
    pub columns: usize,
}

impl Figure {
    /// An empty figure with `columns` panels per row.
    pub fn new(title: impl Into<String>, columns: usize) -> Figure {
        Figure {
            title: title.into(),
            panels: Vec::new(),
            columns,
        }
    }

    /// This figure with `panel` added after the others.
    pub fn with_panel(mut self, panel: impl Into<Panel>) -> Figure {
        self.panels.push(panel.into());
        self
    }

    /// The size of one grid cell: the largest panel width and height.
    fn cell_size(&self) -> (u32, u32) {
        self.panels
            .iter()
            .map(Panel::size)
            .fold((0, 0), |(w, h), (pw, ph)| (w.max(pw), h.max(ph)))
    }

    /// The height of the title strip in image pixels for cells of `cell` size, 0 without a
    /// title.
    fn title_height(&self, cell: (u32, u32)) -> u32 {
        if self.title.is_empty() {
            0
        } else {
            Metrics::new(cell.0, cell.1).px(44.0) / SUPERSAMPLE
        }
    }

    /// The image size: `columns` × rows cells plus the title strip.
    ///
    /// Errors: [`PlotError::Empty`] without panels, [`PlotError::Layout`] for zero columns.
    pub fn size(&self) -> Result<(u32, u32), PlotError> {
        let plot = || plot_name(&self.title);
        if self.panels.is_empty() {
            return Err(PlotError::Empty {
                plot: plot(),
                what: "panels",
            });
        }
        if self.columns == 0 {
            return Err(PlotError::Layout {
                plot: plot(),
                reason: "a figure needs at least one column".to_string(),
            });
        }
        let cell = self.cell_size();
        let columns = self.columns.min(self.panels.len()) as u32;
        let rows = self.panels.len().div_ceil(self.columns) as u32;
        let width = cell.0.saturating_mul(columns);
        let height = cell
            .1
            .saturating_mul(rows)
            .saturating_add(self.title_height(cell));
        Ok((width, height))
    }

    /// Draws all panels into one image of [`Figure::size`].
    ///
    /// Errors: those of [`Figure::size`], a panel size too small for its axes, and any error of
    /// a panel's data (see [`LinePlot::render`] and [`BarChart::render`]).
    pub fn render(&self) -> Result<Bitmap, PlotError> {
        let size = self.size()?;
        let cell = self.cell_size();
        for panel in &self.panels {
            check_size(panel.title(), cell)?;
        }
        check_size(&self.title, size)?;
        let columns = self.columns.min(self.panels.len());
        let rows = self.panels.len().div_ceil(self.columns);
        let (bitmap, ()) = render_with(&self.title, size, |root| {
            let title_height = self.title_height(cell) * SUPERSAMPLE;
            let (title_area, grid) = root.split_vertically(title_height);
            if title_height > 0 {
                let metrics = Metrics::new(cell.0, cell.1);
                let font = metrics.text(26.0).pos(Pos::new(HPos::Center, VPos::Center));
                let centre = (root.dim_in_pixel().0 as i32 / 2, title_height as i32 / 2);
                title_area
                    .draw(&Text::new(self.title.as_str(), centre, font))
                    .map_err(draw_error(&self.title))?;
            }
            let cells = grid.split_evenly((rows, columns));
            for (panel, area) in self.panels.iter().zip(&cells) {
                panel.draw_on(area)?;
            }
            Ok(())
        })?;
        Ok(bitmap)
    }

    /// Draws the figure and writes it as a PNG file at `path`, atomically (see
    /// [`Bitmap::write_png`]).
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        self.render()?.write_png(path)
    }
}
