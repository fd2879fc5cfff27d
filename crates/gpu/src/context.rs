//! `context`: the wgpu instance, adapter, device and queue, found headless (no window, no
//! display). One context serves any number of scenes and frames.

use thiserror::Error;

/// Why no GPU context could be made.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (wgpu saw none on Vulkan, Metal, DX12 or GL); on Linux without a GPU install Mesa's lavapipe: \
         `apt-get install mesa-vulkan-drivers libvulkan1`, or use `--backend cpu`"
    )]
    NoAdapter,
    #[error("no GPU adapter matches HYBRID_ADAPTER=`{wanted}` (found: {found})")]
    NoMatchingAdapter { wanted: String, found: String },
    #[error("the GPU adapter `{adapter}` refused a device: {source}")]
    RequestDevice {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    #[error("the GPU adapter `{adapter}` cannot run this backend: {why}")]
    Unsupported { adapter: String, why: String },
    #[error("no GPU adapter can run this backend ({which}): {why}")]
    NoneUsable { which: String, why: String },
    #[error("the scene does not fit the GPU adapter `{adapter}`: {why}")]
    TooLarge { adapter: String, why: String },
    #[error("GPU error: {0}")]
    Device(String),
}

/// Which adapters a context may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdapterChoice {
    /// Any adapter, best first (discrete, integrated, virtual, then software ones such as
    /// lavapipe). `--backend gpu`.
    Any,
    /// Only hardware GPUs (not a CPU/software adapter). `--backend auto` tries this first and
    /// falls back to the CPU backend when it fails.
    HardwareOnly,
}

/// What the chosen adapter is, for reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdapterSummary {
    pub name: String,
    /// "vulkan", "metal", "dx12", "gl".
    pub backend: String,
    /// "discrete-gpu", "integrated-gpu", "virtual-gpu", "cpu", "other".
    pub device_type: String,
    pub driver: String,
}

/// Device and queue, with what the adapter offers that the backend cares about.
pub struct GpuContext {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub summary: AdapterSummary,
    /// Timestamp queries at pass boundaries are available (per-stage GPU times).
    pub timestamps: bool,
    /// The adapter offers wgpu's ray queries with acceleration structures
    /// (`EXPERIMENTAL_RAY_QUERY`, e.g. Vulkan's VK_KHR_ray_query): the device was opened with them
    /// and the trace can run in hardware (`crate::accel`).
    pub ray_query: bool,
}

impl GpuContext {
    /// Finds an adapter (best first; `HYBRID_ADAPTER=<substring>` picks one by name) and opens a
    /// device with the adapter's own limits (large scenes need big storage buffers).
    pub fn new(choice: AdapterChoice) -> Result<Self, GpuError> {
        // Vulkan, Metal and DX12 first; GL only where none of those has an adapter (a GL instance
        // without a display logs EGL errors, and GL adapters lack features the passes use).
        // WGPU_BACKEND (e.g. `gl`) overrides the choice.
        let instance_for = |backends: wgpu::Backends| {
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
            desc.backends = backends;
            wgpu::Instance::new(desc.with_env())
        };
        let mut instance = instance_for(wgpu::Backends::PRIMARY);
        let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        if adapters.is_empty() {
            instance = instance_for(wgpu::Backends::GL);
            adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        }
        let hardware_only = choice == AdapterChoice::HardwareOnly;
        let adapter = pick_adapter(adapters, hardware_only, "every adapter found")?;
        Self::open(instance, adapter)
    }

    /// Like [`GpuContext::new`] with [`AdapterChoice::Any`], but on the caller's `instance` and
    /// only with adapters that can present to `surface` (a window's), so the same device renders
    /// the frame and draws it into the window. `HYBRID_ADAPTER=<substring>` still picks by name.
    pub fn for_surface(instance: wgpu::Instance, surface: &wgpu::Surface<'_>) -> Result<Self, GpuError> {
        let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        adapters.retain(|a| a.is_surface_supported(surface));
        let adapter = pick_adapter(adapters, false, "every adapter that can present to the window")?;
        Self::open(instance, adapter)
    }

    /// Opens a device on `adapter` with the adapter's own limits (large scenes need big storage
    /// buffers) and timestamp queries where offered.
    fn open(instance: wgpu::Instance, adapter: wgpu::Adapter) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let summary = AdapterSummary {
            name: info.name.clone(),
            backend: format!("{:?}", info.backend).to_lowercase(),
            device_type: device_type_name(info.device_type).into(),
            driver: format!("{} {}", info.driver, info.driver_info).trim().to_string(),
        };
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let ray_query = ray_query_missing(&adapter).is_none();
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let mut experimental_features = wgpu::ExperimentalFeatures::disabled();
        if ray_query {
            required_features |= wgpu::Features::EXPERIMENTAL_RAY_QUERY;
            // SAFETY: interop point with wgpu's experimental ray-query API: wgpu asks the caller
            // to acknowledge that its experimental features may still have bugs. Only requested
            // where the adapter offers ray queries; the hardware-path pipelines (separate
            // variants) are the only users, and the software path never touches them.
            experimental_features = unsafe { wgpu::ExperimentalFeatures::enabled() };
        }
        let desc = wgpu::DeviceDescriptor {
            label: Some("hybrid"),
            required_features,
            required_limits: adapter.limits(),
            experimental_features,
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&desc))
            .map_err(|source| GpuError::RequestDevice { adapter: summary.name.clone(), source })?;
        Ok(Self { instance, adapter, device, queue, summary, timestamps, ray_query })
    }

    /// Waits until the GPU has finished everything submitted so far.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| GpuError::Device(e.to_string()))
    }

    /// A storage buffer holding `bytes` (an empty array gets 128 zero bytes: one element of the
    /// largest struct the shaders read), or `TooLarge` when it exceeds the device's binding limit.
    pub fn storage_buffer(&self, label: &str, bytes: &[u8]) -> Result<wgpu::Buffer, GpuError> {
        use wgpu::util::DeviceExt;
        if bytes.len() as u64 > self.max_storage_binding() {
            return Err(GpuError::TooLarge {
                adapter: self.summary.name.clone(),
                why: format!("{label} needs {} MiB, the device binds at most {} MiB", bytes.len() >> 20, self.max_storage_binding() >> 20),
            });
        }
        let zeros = [0u8; 128];
        let contents = if bytes.is_empty() { &zeros[..] } else { bytes };
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        }))
    }

    /// The largest storage buffer one binding may hold on this device.
    pub fn max_storage_binding(&self) -> u64 {
        self.device.limits().max_storage_buffer_binding_size
    }
}

/// Why `adapter` cannot trace in hardware (`None` when it can): it needs wgpu's ray queries
/// (`EXPERIMENTAL_RAY_QUERY`: acceleration structures and `ray_query` in WGSL) and a fourth bind
/// group (the hardware-path pipelines bind the acceleration structure at group 3).
/// `HYBRID_RAY_QUERY=off` hides the feature (the device is opened without it), so the fallback and
/// `--rt hw`'s error can be seen on an adapter that has it.
pub fn ray_query_missing(adapter: &wgpu::Adapter) -> Option<String> {
    if std::env::var("HYBRID_RAY_QUERY").is_ok_and(|v| v == "off") {
        return Some("HYBRID_RAY_QUERY=off hides the adapter's ray queries".into());
    }
    if !adapter.features().contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY) {
        return Some(
            "the adapter has no ray queries (wgpu's EXPERIMENTAL_RAY_QUERY; on Vulkan VK_KHR_ray_query and VK_KHR_acceleration_structure)"
                .into(),
        );
    }
    let l = adapter.limits();
    if l.max_bind_groups < 4 {
        return Some(format!("bind groups: {}, the hardware path needs 4", l.max_bind_groups));
    }
    if l.max_acceleration_structures_per_shader_stage < 1 {
        return Some("no acceleration structure may be bound to a shader stage".into());
    }
    None
}

/// What the passes need beyond wgpu's defaults: compute shaders, the G-buffer's 8 colour targets
/// (68 bytes per pixel), 16 storage buffers per stage (the trace passes bind 15), 3 bind groups,
/// and every frame target's format usable as the frame uses it (rendered to, sampled, copied and,
/// but for depth, written as a storage texture: OpenGL adapters fail this, e.g. llvmpipe's GL
/// cannot render to `Rgba32Float`). `None` when the adapter has all of it, else what it lacks.
fn missing_capability(adapter: &wgpu::Adapter) -> Option<String> {
    if !adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS) {
        return Some("no compute shaders".into());
    }
    let l = adapter.limits();
    let needs = [
        ("colour attachments", l.max_color_attachments, 8),
        ("colour attachment bytes per sample", l.max_color_attachment_bytes_per_sample, 68),
        ("storage buffers per shader stage", l.max_storage_buffers_per_shader_stage, 16),
        ("bind groups", l.max_bind_groups, 3),
    ];
    if let Some((what, has, need)) = needs.iter().find(|(_, has, need)| has < need) {
        return Some(format!("{what}: {has}, needs {need}"));
    }
    let lacking: Vec<String> = crate::targets::TARGET_FORMATS
        .iter()
        .filter_map(|&format| {
            let features = adapter.get_texture_format_features(format);
            let usages = crate::targets::target_usages(format);
            let mut missing = usage_names(usages - features.allowed_usages);
            if usages.contains(wgpu::TextureUsages::STORAGE_BINDING)
                && !features.flags.contains(wgpu::TextureFormatFeatureFlags::STORAGE_WRITE_ONLY)
                && !missing.contains(&"storage")
            {
                missing.push("storage");
            }
            (!missing.is_empty()).then(|| format!("{format:?} cannot be used as {}", missing.join(", ")))
        })
        .collect();
    (!lacking.is_empty()).then(|| format!("texture formats the frame needs: {}", lacking.join("; ")))
}

/// Plain names of texture usages, for messages.
fn usage_names(usages: wgpu::TextureUsages) -> Vec<&'static str> {
    [
        (wgpu::TextureUsages::RENDER_ATTACHMENT, "render target"),
        (wgpu::TextureUsages::TEXTURE_BINDING, "sampled texture"),
        (wgpu::TextureUsages::STORAGE_BINDING, "storage"),
        (wgpu::TextureUsages::COPY_SRC, "copy source"),
        (wgpu::TextureUsages::COPY_DST, "copy destination"),
    ]
    .into_iter()
    .filter(|(u, _)| usages.contains(*u))
    .map(|(_, name)| name)
    .collect()
}

/// The best of `adapters` (ranked; `HYBRID_ADAPTER=<substring>` picks one by name), skipping
/// software ones when `hardware_only` and those that cannot run every pass (with the reasons, if
/// none is left; `which` names the set in that error).
fn pick_adapter(mut adapters: Vec<wgpu::Adapter>, hardware_only: bool, which: &str) -> Result<wgpu::Adapter, GpuError> {
    adapters.sort_by_key(|a| rank(&a.get_info()));
    if let Ok(wanted) = std::env::var("HYBRID_ADAPTER") {
        let found = adapters.iter().map(|a| a.get_info().name).collect::<Vec<_>>().join(", ");
        adapters.retain(|a| a.get_info().name.to_lowercase().contains(&wanted.to_lowercase()));
        if adapters.is_empty() {
            return Err(GpuError::NoMatchingAdapter { wanted, found });
        }
    }
    if hardware_only {
        adapters.retain(|a| !matches!(a.get_info().device_type, wgpu::DeviceType::Cpu | wgpu::DeviceType::Other));
    }
    let mut refused = Vec::new();
    adapters.retain(|a| match missing_capability(a) {
        None => true,
        Some(why) => {
            let info = a.get_info();
            refused.push((format!("{} ({:?})", info.name, info.backend), why));
            false
        }
    });
    adapters.into_iter().next().ok_or_else(|| match refused.len() {
        0 => GpuError::NoAdapter,
        1 => {
            let (adapter, why) = refused.swap_remove(0);
            GpuError::Unsupported { adapter, why }
        }
        _ => GpuError::NoneUsable {
            which: which.into(),
            why: refused.iter().map(|(a, why)| format!("{a}: {why}")).collect::<Vec<_>>().join("; "),
        },
    })
}

/// Sort key: hardware before software, Vulkan/Metal/DX12 before GL.
fn rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let kind = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    let api = match info.backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        _ => 1,
    };
    (kind, api)
}

fn device_type_name(t: wgpu::DeviceType) -> &'static str {
    match t {
        wgpu::DeviceType::DiscreteGpu => "discrete-gpu",
        wgpu::DeviceType::IntegratedGpu => "integrated-gpu",
        wgpu::DeviceType::VirtualGpu => "virtual-gpu",
        wgpu::DeviceType::Cpu => "cpu",
        wgpu::DeviceType::Other => "other",
    }
}

/// Keeps the adapter probe quiet where `XDG_RUNTIME_DIR` is unset (CI, ssh, containers): the
/// Vulkan loader's window-system probing (libwayland) then prints `error: XDG_RUNTIME_DIR is
/// invalid or not set` on every instance, though nothing is wrong. Pointing the variable at a
/// directory that does not exist keeps libwayland quiet and makes it find no display, which is
/// the truth when the variable was unset (a Wayland session always sets it). Nothing is created.
///
/// Call it first thing in `main`, before any thread starts (it sets an environment variable).
pub fn quiet_window_system_probe() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| !d.is_empty()) {
        return;
    }
    let dir = std::env::temp_dir().join("hybrid-no-xdg-runtime-dir");
    // SAFETY: interop point with the Vulkan loader/libwayland, which read XDG_RUNTIME_DIR.
    // `set_var` is unsound only while other threads read the environment; the documented
    // contract of this function is that it runs at the start of `main`, before any thread exists.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir) };
}
