//! CLAP's GUI extension: the editor ([`crate::editor`]) on X11, embedded in the host's window or
//! floating, at the host's scale, resizable; opened, closed and reopened on the main thread.
//! The size it reports and takes is in physical pixels, as CLAP's X11 API counts them.

use crate::editor::{self, X11Parent};
use crate::MainThread;
use clack_extensions::gui::{
    AspectRatioStrategy, GuiApiType, GuiConfiguration, GuiResizeHints, GuiSize, PluginGuiImpl,
    Window as ClapWindow,
};
use clack_plugin::prelude::PluginError;

/// The editor's side of the main thread.
#[derive(Default)]
pub struct Gui {
    /// The open window, if any.
    window: Option<editor::Window>,
    /// Created (by `create`), floating or embedded.
    created: Option<bool>,
    /// The host's scale factor.
    scale: f64,
    /// The size in logical pixels.
    size: (f64, f64),
}

impl Gui {
    fn physical(&self) -> GuiSize {
        let (width, height) = editor::physical(self.size, self.scale);
        GuiSize { width, height }
    }

    fn open(
        &mut self,
        main: &MainThread<'_>,
        parent: Option<&X11Parent>,
    ) -> Result<(), PluginError> {
        let window = editor::Window::open(main.shown(), parent, self.scale.max(1.0))
            .map_err(|e| PluginError::Error(e.into()))?;
        window
            .resize(self.size.0, self.size.1)
            .map_err(|e| PluginError::Error(e.into()))?;
        self.window = Some(window);
        Ok(())
    }
}

impl PluginGuiImpl for MainThread<'_> {
    fn is_api_supported(&self, configuration: GuiConfiguration) -> bool {
        configuration.api_type == GuiApiType::X11
    }

    fn get_preferred_api(&self) -> Option<GuiConfiguration<'_>> {
        Some(GuiConfiguration {
            api_type: GuiApiType::X11,
            is_floating: false,
        })
    }

    fn create(&self, configuration: GuiConfiguration) -> Result<(), PluginError> {
        if configuration.api_type != GuiApiType::X11 {
            return Err(PluginError::Message("unacorda's editor draws on X11 only"));
        }
        let mut gui = self.gui.borrow_mut();
        *gui = Gui {
            created: Some(configuration.is_floating),
            scale: 1.0,
            size: (editor::WIDTH, editor::HEIGHT),
            ..Gui::default()
        };
        Ok(())
    }

    fn destroy(&self) {
        // The window's thread is joined as it drops.
        *self.gui.borrow_mut() = Gui::default();
    }

    fn set_scale(&self, scale: f64) -> Result<(), PluginError> {
        if !(0.25..=8.0).contains(&scale) {
            return Err(PluginError::Message("a scale factor outside 0.25-8"));
        }
        self.gui.borrow_mut().scale = scale;
        Ok(())
    }

    fn get_size(&self) -> Option<GuiSize> {
        let gui = self.gui.borrow();
        gui.created.map(|_| gui.physical())
    }

    fn can_resize(&self) -> bool {
        true
    }

    fn get_resize_hints(&self) -> Option<GuiResizeHints> {
        Some(GuiResizeHints {
            can_resize_horizontally: true,
            can_resize_vertically: true,
            strategy: AspectRatioStrategy::Disregard,
        })
    }

    fn adjust_size(&self, size: GuiSize) -> Option<GuiSize> {
        let (width, height) = editor::smallest(self.gui.borrow().scale);
        Some(GuiSize {
            width: size.width.max(width),
            height: size.height.max(height),
        })
    }

    fn set_size(&self, size: GuiSize) -> Result<(), PluginError> {
        let mut gui = self.gui.borrow_mut();
        gui.size = editor::logical(size.width, size.height, gui.scale);
        match &gui.window {
            Some(w) => w
                .resize(gui.size.0, gui.size.1)
                .map_err(|e| PluginError::Error(e.into())),
            None => Ok(()),
        }
    }

    fn set_parent(&self, window: ClapWindow) -> Result<(), PluginError> {
        let id = window
            .as_x11_handle()
            .ok_or(PluginError::Message("not an X11 window"))?;
        let mut gui = self.gui.borrow_mut();
        gui.window = None;
        gui.open(self, Some(&X11Parent(id)))
    }

    fn set_transient(&self, _window: ClapWindow) -> Result<(), PluginError> {
        Ok(())
    }

    fn show(&self) -> Result<(), PluginError> {
        let mut gui = self.gui.borrow_mut();
        match (&gui.window, gui.created) {
            (Some(w), _) => w.show().map_err(|e| PluginError::Error(e.into())),
            // A floating editor opens its own window when first shown.
            (None, Some(true)) => gui.open(self, None),
            (None, _) => Err(PluginError::Message(
                "no parent window to show the editor in",
            )),
        }
    }

    fn hide(&self) -> Result<(), PluginError> {
        match &self.gui.borrow().window {
            Some(w) => w.hide().map_err(|e| PluginError::Error(e.into())),
            None => Ok(()),
        }
    }
}
