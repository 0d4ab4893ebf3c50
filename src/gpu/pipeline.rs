//! Pipelines from a shader module, entry points and bind group layouts, with the few options
//! the stages use (pipeline constants, triangle strips, culling, a depth test, blending); and
//! the buffers and views the stages make the same way.

use wgpu::{BindGroupLayout, ShaderModule};

/// Pipeline constants: `override` names of the shader and their values.
pub type Constants<'a> = &'a [(&'a str, f64)];

/// A pipeline layout of `layouts` (bind group 0, 1, ... in order).
pub fn pipeline_layout(
    device: &wgpu::Device,
    label: &str,
    layouts: &[&BindGroupLayout],
) -> wgpu::PipelineLayout {
    let layouts: Vec<Option<&BindGroupLayout>> = layouts.iter().copied().map(Some).collect();
    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    })
}

/// The compute pipeline of `module`'s `entry` over bind groups of `layouts`.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &ShaderModule,
    entry: &str,
    layouts: &[&BindGroupLayout],
) -> wgpu::ComputePipeline {
    compute_pipeline_with_constants(device, label, module, entry, layouts, &[])
}

/// Like [`compute_pipeline`], with pipeline `constants` (the shader's `override`s).
pub fn compute_pipeline_with_constants(
    device: &wgpu::Device,
    label: &str,
    module: &ShaderModule,
    entry: &str,
    layouts: &[&BindGroupLayout],
    constants: Constants<'_>,
) -> wgpu::ComputePipeline {
    compute(
        device,
        label,
        module,
        entry,
        Some(&pipeline_layout(device, label, layouts)),
        constants,
    )
}

/// The compute pipeline of `module`'s `entry`, its layout derived from the shader (read it
/// back with `get_bind_group_layout`).
pub fn compute_pipeline_auto(
    device: &wgpu::Device,
    label: &str,
    module: &ShaderModule,
    entry: &str,
) -> wgpu::ComputePipeline {
    compute(device, label, module, entry, None, &[])
}

fn compute(
    device: &wgpu::Device,
    label: &str,
    module: &ShaderModule,
    entry: &str,
    layout: Option<&wgpu::PipelineLayout>,
    constants: Constants<'_>,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout,
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

/// A render pipeline of one vertex and one fragment entry point of a module, no vertex
/// buffers and one colour target; made by [`render_pipeline`], finished by [`Self::build`].
#[must_use = "a render pipeline is made by `build`"]
pub struct RenderPipelineBuilder<'a> {
    label: &'a str,
    module: &'a ShaderModule,
    entries: (&'a str, &'a str),
    target: Option<wgpu::ColorTargetState>,
    second: Option<wgpu::ColorTargetState>,
    layouts: &'a [&'a BindGroupLayout],
    constants: (Constants<'a>, Constants<'a>),
    primitive: wgpu::PrimitiveState,
    depth: Option<wgpu::DepthStencilState>,
    multisample: wgpu::MultisampleState,
}

/// A render pipeline drawing `module`'s `vertex` and `fragment` entry points into `target`
/// (a format converts into a target written whole, unblended); by default no bind groups, no
/// constants, triangle lists without culling, no depth.
pub fn render_pipeline<'a>(
    label: &'a str,
    module: &'a ShaderModule,
    (vertex, fragment): (&'a str, &'a str),
    target: impl Into<wgpu::ColorTargetState>,
) -> RenderPipelineBuilder<'a> {
    RenderPipelineBuilder {
        label,
        module,
        entries: (vertex, fragment),
        target: Some(target.into()),
        second: None,
        layouts: &[],
        constants: (&[], &[]),
        primitive: Default::default(),
        depth: None,
        multisample: Default::default(),
    }
}

impl<'a> RenderPipelineBuilder<'a> {
    /// Bind groups 0, 1, ... of these layouts.
    pub fn layouts(self, layouts: &'a [&'a BindGroupLayout]) -> Self {
        Self { layouts, ..self }
    }

    /// Pipeline constants of the vertex and of the fragment stage.
    pub fn constants(self, vertex: Constants<'a>, fragment: Constants<'a>) -> Self {
        Self {
            constants: (vertex, fragment),
            ..self
        }
    }

    /// A second colour target, of `format`, written whole.
    pub fn second_target(self, format: wgpu::TextureFormat) -> Self {
        Self {
            second: Some(format.into()),
            ..self
        }
    }

    /// No colour target: a depth-only pass (a shadow map).
    pub fn depth_only(self) -> Self {
        Self {
            target: None,
            ..self
        }
    }

    /// Triangle strips, both faces drawn (the grass blades).
    pub fn triangle_strips(self) -> Self {
        Self {
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleStrip,
                cull_mode: None,
                ..Default::default()
            },
            ..self
        }
    }

    /// Back faces culled.
    pub fn cull_back(self) -> Self {
        Self {
            primitive: wgpu::PrimitiveState {
                cull_mode: Some(wgpu::Face::Back),
                ..self.primitive
            },
            ..self
        }
    }

    /// A depth test against a target of `format` by `compare`, writing depth when `write`.
    pub fn depth(
        self,
        format: wgpu::TextureFormat,
        write: bool,
        compare: wgpu::CompareFunction,
    ) -> Self {
        Self {
            depth: Some(wgpu::DepthStencilState {
                format,
                depth_write_enabled: Some(write),
                depth_compare: Some(compare),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            ..self
        }
    }

    /// Into a target of `count` samples per pixel; with `alpha_to_coverage`, the fragment's
    /// alpha chooses how many of a pixel's samples it covers.
    pub fn multisample(self, count: u32, alpha_to_coverage: bool) -> Self {
        Self {
            multisample: wgpu::MultisampleState {
                count,
                mask: !0,
                alpha_to_coverage_enabled: alpha_to_coverage,
            },
            ..self
        }
    }

    /// The pipeline.
    pub fn build(self, device: &wgpu::Device) -> wgpu::RenderPipeline {
        let layout = pipeline_layout(device, self.label, self.layouts);
        let targets: Vec<Option<wgpu::ColorTargetState>> = self
            .target
            .into_iter()
            .chain(self.second)
            .map(Some)
            .collect();
        let options = |constants| wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        };
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(self.label),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: self.module,
                entry_point: Some(self.entries.0),
                compilation_options: options(self.constants.0),
                buffers: &[],
            },
            primitive: self.primitive,
            depth_stencil: self.depth,
            multisample: self.multisample,
            fragment: Some(wgpu::FragmentState {
                module: self.module,
                entry_point: Some(self.entries.1),
                compilation_options: options(self.constants.1),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        })
    }
}

/// A buffer of `size` bytes for `usage`, zeroed.
pub fn buffer(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}

/// A view of every layer of `texture` as a 2D array (the atlas and the staging textures).
pub fn array_view(texture: &wgpu::Texture) -> wgpu::TextureView {
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// A bind group that reads a depth target, made again only when the target's view changes
/// (a new frame's target, or a resize): the passes that read the depth keep one each.
///
/// It binds the caller's view itself, not a view of its whole texture: a view of one layer or
/// one mip level of a larger texture is read where it is drawn. (The renderer's depth formats
/// have no stencil, so the view's whole aspect is its depth.)
#[derive(Default)]
pub struct DepthBound(Option<(wgpu::TextureView, wgpu::BindGroup)>);

impl DepthBound {
    /// The bind group for `depth`, made by `make` from it when `depth` is not the view of the
    /// last one.
    pub fn get(
        &mut self,
        depth: &wgpu::TextureView,
        make: impl FnOnce(&wgpu::TextureView) -> wgpu::BindGroup,
    ) -> &wgpu::BindGroup {
        if self.0.as_ref().is_none_or(|(v, _)| v != depth) {
            self.0 = Some((depth.clone(), make(depth)));
        }
        &self.0.as_ref().expect("made above").1
    }

    /// Forgets the bind group (what it binds besides the depth has changed).
    pub fn clear(&mut self) {
        self.0 = None;
    }
}
