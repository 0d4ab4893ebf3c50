//! Bind group layouts and bind groups one line per binding, so that a stage's set-up reads like
//! its WGSL header (in the spirit of Bevy's `BindGroupLayoutEntries`):
//!
//! ```
//! use verdant::gpu::layout::*;
//! let entries = sequential(
//!     wgpu::ShaderStages::COMPUTE,
//!     [uniform_buffer(), texture_depth_2d(), texture_storage_2d(wgpu::TextureFormat::R32Float)],
//! );
//! assert_eq!(entries[2].binding, 2);
//! ```

use std::num::NonZeroU64;

use wgpu::{
    BindGroupLayoutEntry, BindingResource, BindingType, BufferBindingType, ShaderStages,
    TextureSampleType, TextureViewDimension,
};

/// The sample type of the float textures the stages read with `textureLoad` (never filtered).
pub const UNFILTERABLE_FLOAT: TextureSampleType = TextureSampleType::Float { filterable: false };

/// One binding of a layout: its type, and the shader stages that see it where they differ from
/// the rest of the layout's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Binding {
    /// What is bound.
    pub ty: BindingType,
    /// The stages that see it; `None`: those given to [`sequential`] or [`with_indices`].
    pub visibility: Option<ShaderStages>,
}

impl From<BindingType> for Binding {
    fn from(ty: BindingType) -> Self {
        Self {
            ty,
            visibility: None,
        }
    }
}

impl Binding {
    /// The same binding, seen by `stages` only.
    pub fn visible_in(self, stages: ShaderStages) -> Self {
        Self {
            visibility: Some(stages),
            ..self
        }
    }

    /// The same buffer binding, bound with a dynamic offset.
    ///
    /// Panics on a binding that is no buffer.
    pub fn dynamic(mut self) -> Self {
        match &mut self.ty {
            BindingType::Buffer {
                has_dynamic_offset, ..
            } => *has_dynamic_offset = true,
            ty => panic!("a dynamic offset needs a buffer binding, not {ty:?}"),
        }
        self
    }

    /// The same buffer binding, checked at bind time to hold at least `bytes` (0: no check).
    ///
    /// Panics on a binding that is no buffer.
    pub fn min_size(mut self, bytes: u64) -> Self {
        match &mut self.ty {
            BindingType::Buffer {
                min_binding_size, ..
            } => *min_binding_size = NonZeroU64::new(bytes),
            ty => panic!("a minimum size needs a buffer binding, not {ty:?}"),
        }
        self
    }
}

fn buffer(ty: BufferBindingType) -> Binding {
    BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    }
    .into()
}

/// `var<uniform>`.
pub fn uniform_buffer() -> Binding {
    buffer(BufferBindingType::Uniform)
}

/// `var<storage, read>`.
pub fn storage_buffer_read_only() -> Binding {
    buffer(BufferBindingType::Storage { read_only: true })
}

/// `var<storage, read_write>`.
pub fn storage_buffer() -> Binding {
    buffer(BufferBindingType::Storage { read_only: false })
}

fn texture(sample_type: TextureSampleType, view_dimension: TextureViewDimension) -> Binding {
    BindingType::Texture {
        sample_type,
        view_dimension,
        multisampled: false,
    }
    .into()
}

/// `texture_2d<T>` of `sample_type`.
pub fn texture_2d(sample_type: TextureSampleType) -> Binding {
    texture(sample_type, TextureViewDimension::D2)
}

/// `texture_2d_array<T>` of `sample_type`.
pub fn texture_2d_array(sample_type: TextureSampleType) -> Binding {
    texture(sample_type, TextureViewDimension::D2Array)
}

/// `texture_depth_2d`.
pub fn texture_depth_2d() -> Binding {
    texture(TextureSampleType::Depth, TextureViewDimension::D2)
}

/// `texture_depth_2d_array`.
pub fn texture_depth_2d_array() -> Binding {
    texture(TextureSampleType::Depth, TextureViewDimension::D2Array)
}

/// `texture_storage_2d<format, write>`.
pub fn texture_storage_2d(format: wgpu::TextureFormat) -> Binding {
    BindingType::StorageTexture {
        access: wgpu::StorageTextureAccess::WriteOnly,
        format,
        view_dimension: TextureViewDimension::D2,
    }
    .into()
}

/// Layout entries numbered from 0 in order, each seen by `visibility` unless it says otherwise.
pub fn sequential(
    visibility: ShaderStages,
    bindings: impl IntoIterator<Item = Binding>,
) -> Vec<BindGroupLayoutEntry> {
    with_indices(visibility, (0..).zip(bindings))
}

/// Layout entries at the given binding numbers (for a layout with gaps), each seen by
/// `visibility` unless it says otherwise.
pub fn with_indices(
    visibility: ShaderStages,
    bindings: impl IntoIterator<Item = (u32, Binding)>,
) -> Vec<BindGroupLayoutEntry> {
    bindings
        .into_iter()
        .map(|(binding, b)| BindGroupLayoutEntry {
            binding,
            visibility: b.visibility.unwrap_or(visibility),
            ty: b.ty,
            count: None,
        })
        .collect()
}

/// A bind group layout of `entries`.
pub fn bind_group_layout(
    device: &wgpu::Device,
    label: &str,
    entries: &[BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries,
    })
}

/// A bind group of `layout` with `resources` bound at 0, 1, 2, ... in order.
pub fn bind_group<'a>(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: impl IntoIterator<Item = BindingResource<'a>>,
) -> wgpu::BindGroup {
    bind_group_with_indices(device, label, layout, (0..).zip(resources))
}

/// A bind group of `layout` with each resource bound at the number beside it.
pub fn bind_group_with_indices<'a>(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: impl IntoIterator<Item = (u32, BindingResource<'a>)>,
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = resources
        .into_iter()
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// A texture view as a binding resource.
pub fn view(view: &wgpu::TextureView) -> BindingResource<'_> {
    BindingResource::TextureView(view)
}

/// The first `bytes` of `buffer` as a binding resource (the window a dynamic offset moves).
pub fn buffer_prefix(buffer: &wgpu::Buffer, bytes: u64) -> BindingResource<'_> {
    BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset: 0,
        size: NonZeroU64::new(bytes),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequential_entries_are_numbered_in_order_and_seen_by_the_given_stages() {
        let e = sequential(
            ShaderStages::COMPUTE,
            [
                uniform_buffer(),
                storage_buffer_read_only(),
                texture_2d_array(TextureSampleType::Uint),
            ],
        );
        assert_eq!(e.iter().map(|e| e.binding).collect::<Vec<_>>(), [0, 1, 2]);
        assert!(e.iter().all(|e| e.visibility == ShaderStages::COMPUTE));
        assert!(e.iter().all(|e| e.count.is_none()));
        assert_eq!(
            e[1].ty,
            BindingType::Buffer {
                ty: BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            }
        );
        assert_eq!(
            e[2].ty,
            BindingType::Texture {
                sample_type: TextureSampleType::Uint,
                view_dimension: TextureViewDimension::D2Array,
                multisampled: false,
            }
        );
    }

    #[test]
    fn indices_gaps_dynamic_offsets_sizes_and_visibility_are_kept() {
        let e = with_indices(
            ShaderStages::VERTEX_FRAGMENT,
            [
                (0, uniform_buffer().dynamic().min_size(24)),
                (6, storage_buffer().visible_in(ShaderStages::VERTEX)),
            ],
        );
        assert_eq!((e[0].binding, e[1].binding), (0, 6));
        assert_eq!(e[0].visibility, ShaderStages::VERTEX_FRAGMENT);
        assert_eq!(e[1].visibility, ShaderStages::VERTEX);
        assert_eq!(
            e[0].ty,
            BindingType::Buffer {
                ty: BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: NonZeroU64::new(24),
            }
        );
        assert_eq!(
            e[1].ty,
            BindingType::Buffer {
                ty: BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            }
        );
    }

    #[test]
    fn textures_read_as_their_wgsl_types() {
        let format = wgpu::TextureFormat::R32Float;
        let e = sequential(
            ShaderStages::FRAGMENT,
            [
                texture_2d(UNFILTERABLE_FLOAT),
                texture_depth_2d(),
                texture_storage_2d(format),
            ],
        );
        assert_eq!(
            e[0].ty,
            BindingType::Texture {
                sample_type: TextureSampleType::Float { filterable: false },
                view_dimension: TextureViewDimension::D2,
                multisampled: false,
            }
        );
        assert_eq!(
            e[1].ty,
            BindingType::Texture {
                sample_type: TextureSampleType::Depth,
                view_dimension: TextureViewDimension::D2,
                multisampled: false,
            }
        );
        assert_eq!(
            e[2].ty,
            BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: TextureViewDimension::D2,
            }
        );
    }

    #[test]
    #[should_panic(expected = "dynamic offset needs a buffer")]
    fn a_texture_has_no_dynamic_offset() {
        let _ = texture_depth_2d().dynamic();
    }
}
