//! Render passes over one colour target (or a few) and at most one depth target, each loaded or cleared
//! as the pass asks and always stored: the only kind of render pass the stages record.

/// A render pass labelled `label` into `color`, and `depth` when given, with their load
/// operations, timed by `timestamp_writes`.
pub fn render_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    color: (&wgpu::TextureView, wgpu::LoadOp<wgpu::Color>),
    depth: Option<(&wgpu::TextureView, wgpu::LoadOp<f32>)>,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    render_pass_into(encoder, label, &[color], depth, timestamp_writes)
}

/// [`render_pass`] into several colour targets (the grass's colour and its motion vectors).
pub fn render_pass_into<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    colors: &[(&wgpu::TextureView, wgpu::LoadOp<wgpu::Color>)],
    depth: Option<(&wgpu::TextureView, wgpu::LoadOp<f32>)>,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    let store = wgpu::StoreOp::Store;
    let color_attachments: Vec<_> = colors
        .iter()
        .map(|&(view, load)| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load, store },
            })
        })
        .collect();
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &color_attachments,
        depth_stencil_attachment: depth.map(|(view, load)| {
            wgpu::RenderPassDepthStencilAttachment {
                view,
                depth_ops: Some(wgpu::Operations { load, store }),
                stencil_ops: None,
            }
        }),
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A render pass of no colour target into the depth target `depth`, cleared to 0 (reverse
/// depth: everything far) and stored: a shadow map's layer.
pub fn depth_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    depth: &wgpu::TextureView,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(0.0),
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
