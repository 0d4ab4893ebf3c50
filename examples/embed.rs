//! verdant inside someone else's wgpu application.
//!
//! The application owns the device, the targets, the camera and a pass of its own; verdant's
//! `Renderer` draws the terrain and grass into the application's targets, recording into the
//! application's command encoder. Headless: the frame is written to a PNG file.
//!
//! ```sh
//! cargo run --example embed -- out/embed.png 640x360
//! ```

use std::time::Duration;

use glam::camera::rh;
use glam::{DVec3, Mat4, Vec3};
use verdant::{Camera, FrameInput, Renderer, RendererOptions, World};

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args.next().unwrap_or_else(|| "embed.png".into());
    let (width, height) = match args.next() {
        Some(size) => {
            let (w, h) = size.split_once('x').ok_or("size must be WIDTHxHEIGHT")?;
            (w.parse()?, h.parse()?)
        }
        None => (640, 360),
    };

    // The application's own device and queue.
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: adapter.limits(),
        ..Default::default()
    }))?;

    // Its own targets. verdant reads the depth target for occlusion culling: TEXTURE_BINDING.
    let target = |format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    use wgpu::TextureUsages as U;
    let color = target(COLOR_FORMAT, U::RENDER_ATTACHMENT | U::COPY_SRC);
    let depth = target(DEPTH_FORMAT, U::RENDER_ATTACHMENT | U::TEXTURE_BINDING);
    let color_view = color.create_view(&Default::default());
    let depth_view = depth.create_view(&Default::default());

    // verdant's renderer over them.
    let world = World::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/worlds/santa-cruz"
    )))?;
    let options = RendererOptions::new(&world, COLOR_FORMAT, DEPTH_FORMAT, width, height);
    let mut renderer = Renderer::new(&device, &queue, world, options)?;

    // Its own camera: at standing height over the meadow, a view and a reverse-Z projection of
    // its own. Positions are world metres (x east, y north, z up) in f64; the view matrix holds
    // the rotation only, so that nothing far from the world's origin jitters.
    let eye = DVec3::new(20230.0, 28202.0, 52.0);
    let look = Vec3::new(0.92, -0.38, -0.1).normalize();
    let view: Mat4 = rh::view::look_to_mat4(Vec3::ZERO, look, Vec3::Z);
    let aspect = width as f32 / height as f32;
    // wgpu's clip space is Direct3D's (depth 0 to 1); reverse-Z: depth 1 at the near plane.
    let proj = rh::proj::directx::perspective_infinite_reverse(55f32.to_radians(), aspect, 0.1);
    let camera = Camera::with_view(eye, view, proj);

    // Load what the first frame needs (later frames stream without waiting).
    renderer.warm_up(&camera, Duration::from_secs(60))?;

    for frame in 0..3 {
        renderer.prepare(&queue, &FrameInput::new(camera, f64::from(frame) / 60.0));
        let mut encoder = device.create_command_encoder(&Default::default());
        // The application's own pass (verdant draws the whole frame over it: terrain and sky).
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("application clear"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::RED),
                    store: wgpu::StoreOp::Store,
                },
            })],
            ..Default::default()
        });
        renderer.record(&mut encoder, &color_view, &depth_view)?;
        queue.submit([encoder.finish()]);
    }

    let pixels = verdant::gpu::read_texture_rgba8(&device, &queue, &color)?;
    let image = image::RgbaImage::from_raw(width, height, pixels).ok_or("image size")?;
    image.save(&out)?;
    if let Some(stats) = renderer.stats() {
        println!(
            "frame {}: {} terrain tiles, {} blades drawn",
            stats.frame,
            stats.tiles_drawn,
            stats.grass.drawn[0] + stats.grass.drawn[1]
        );
    }
    println!("wrote {out}");
    Ok(())
}
