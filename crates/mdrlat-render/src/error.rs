//! The one error type of the crate.

use std::path::PathBuf;

/// Why a picture or animation could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// Creating or writing a file failed (a missing directory, no permission, a full disk).
    #[error("cannot write {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The PNG encoder failed.
    #[error("cannot encode PNG {}: {source}", path.display())]
    Png {
        /// The file, or `<memory>` for [`Image::encode_png`](crate::Image::encode_png).
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
    /// The GIF encoder failed (including a failed write to its output).
    #[error("cannot encode GIF {}: {source}", path.display())]
    Gif {
        /// The file, or `<stream>` for a [`GifWriter`](crate::GifWriter) over a writer.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: gif::EncodingError,
    },
    /// A picture or animation size the format cannot hold.
    #[error("{}: bad size {width}x{height}: {why}", path.display())]
    Size {
        /// The file, or `<memory>` / `<stream>`.
        path: PathBuf,
        /// Width asked for, pixels.
        width: u32,
        /// Height asked for, pixels.
        height: u32,
        /// What is wrong with it.
        why: &'static str,
    },
}
