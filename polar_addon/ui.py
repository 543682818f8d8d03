"""Polar's panels in the Render and View Layer properties, and the polarisation of lights and emission."""

import bpy


class _PolarPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {"POLAR"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class POLAR_PT_sampling(_PolarPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_context = "render"

    def draw(self, context):
        p = context.scene.polar
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(p, "preview_samples", text="Viewport")
        # Render sampling laid out as Cycles' Sampling ▸ Render panel.
        col = layout.column(heading="Noise Threshold", align=True)
        row = col.row(align=True)
        row.prop(p, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = p.use_adaptive_sampling
        sub.prop(p, "adaptive_threshold", text="")
        adaptive = p.use_adaptive_sampling or p.time_limit > 0        # a time limit alone: budget mode
        col = layout.column(align=True)
        sub = col.column(align=True)
        sub.active = adaptive
        sub.prop(p, "noise_quantity")
        col.prop(p, "samples", text="Max Samples" if adaptive else "Render")
        sub = col.column(align=True)
        sub.active = adaptive
        sub.prop(p, "adaptive_min_samples", text="Min Samples")
        col.prop(p, "time_limit")
        layout.operator("polar.estimate_cost", icon="TIME")
        for line in p.estimate_report.splitlines():
            layout.label(text=line)
        # Denoise as Cycles' Sampling ▸ Render ▸ Denoise: a check box heading its settings.
        col = layout.column(heading="Denoise", align=True)
        col.prop(p, "use_denoising", text="")
        sub = col.column(align=True)
        sub.active = p.use_denoising
        sub.prop(p, "denoising_clamp_dop")
        layout.prop(p, "max_bounces")
        row = layout.row(align=True)
        row.prop(p, "seed")
        row.prop(p, "use_animated_seed", text="", icon="TIME")
        layout.prop(p, "sampler")
        sub = layout.row()
        sub.active = p.sampler != "INDEPENDENT"
        sub.prop(p, "halves")
        c = getattr(context.scene, "cycles", None)
        if c is not None and hasattr(c, "use_light_tree"):       # Cycles' own switch: a file keeps one setting
            layout.prop(c, "use_light_tree", text="Light Tree")


class POLAR_PT_light_model(_PolarPanel, bpy.types.Panel):
    bl_label = "Polarisation & Spectrum"
    bl_context = "render"

    def draw(self, context):
        p = context.scene.polar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "polarisation")
        layout.prop(p, "skip_clear_layers")
        layout.prop(p, "spectral")
        sub = layout.row()
        sub.enabled = p.spectral == "MONO"
        sub.prop(p, "wavelength_nm")


class POLAR_PT_performance(_PolarPanel, bpy.types.Panel):
    bl_label = "Performance"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        p = context.scene.polar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "threads")
        layout.prop(p, "parallel")
        layout.prop(p, "batch_rays")
        col = layout.column(align=True)
        col.prop(p, "world_bake_resolution")
        col.prop(p, "world_bake_samples", text="Samples")
        layout.prop(p, "texture_bake_resolution")
        layout.prop(p, "volume_mie")


class POLAR_PT_polariser(_PolarPanel, bpy.types.Panel):
    bl_label = "Virtual Polariser"
    bl_context = "render"

    def draw(self, context):
        p = context.scene.polar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "polariser_type")
        if p.polariser_type in ("LINEAR", "RETARDER"):
            layout.prop(p, "polariser_angle")
            layout.prop(p, "polariser_extinction")
        if p.polariser_type == "RETARDER":
            layout.prop(p, "retarder_angle")
            layout.prop(p, "retardance")
        col = layout.column(heading="Mosaic")
        col.prop(p, "mosaic_angles", text="Angles")
        col.prop(p, "mosaic_extinction", text="Extinction")
        layout.operator("polar.add_virtual_polariser", icon="NODE_COMPOSITING")


class POLAR_PT_passes(_PolarPanel, bpy.types.Panel):
    bl_label = "Polarisation Passes"
    bl_context = "view_layer"

    def draw(self, context):
        s = context.view_layer.polar
        layout = self.layout
        col = layout.column(heading="Stokes", align=True)
        for name in ("s0", "s1", "s2", "s3"):
            col.prop(s, f"use_pass_{name}")
        col = layout.column(heading="Derived", align=True)
        for name in ("dop", "dolp", "aolp", "docp", "polariser", "polarisation_mosaic"):
            col.prop(s, f"use_pass_{name}")
        col = layout.column(heading="False Colour", align=True)
        for name in ("visdop", "viss1", "viss2", "viss3", "visaolp"):
            col.prop(s, f"use_pass_{name}")
        col = layout.column(heading="Adaptive Sampling", align=True)
        col.prop(s, "use_pass_noise")
        col = layout.column(heading="Denoising Data", align=True)
        col.prop(s, "use_pass_denoising_albedo")
        col.prop(s, "use_pass_denoising_normal")
        layout.operator("polar.add_polar_denoise", icon="NODE_COMPOSITING")


class POLAR_PT_data_passes(_PolarPanel, bpy.types.Panel):
    """Cycles' data passes and Cryptomatte as Polar writes them (polar_addon.passes; the World's Mist panel
    sets the Mist pass's ramp)."""
    bl_label = "Data & Cryptomatte Passes"
    bl_context = "view_layer"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layer = context.view_layer
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column(heading="Data", align=True)
        for prop in ("use_pass_z", "use_pass_mist", "use_pass_position", "use_pass_normal", "use_pass_vector",
                     "use_pass_uv"):
            col.prop(layer, prop)
        col = layout.column(heading="Indexes", align=True)
        col.prop(layer, "use_pass_object_index")
        col.prop(layer, "use_pass_material_index")
        col = layout.column(heading="Alpha Threshold")
        col.prop(layer, "pass_alpha_threshold", text="")
        col = layout.column(heading="Cryptomatte", align=True)
        col.prop(layer, "use_pass_cryptomatte_object", text="Object")
        col.prop(layer, "use_pass_cryptomatte_material", text="Material")
        col.prop(layer, "use_pass_cryptomatte_asset", text="Asset")
        sub = layout.column()
        sub.active = any((layer.use_pass_cryptomatte_object, layer.use_pass_cryptomatte_material,
                          layer.use_pass_cryptomatte_asset))
        sub.prop(layer, "pass_cryptomatte_depth", text="Levels")


def draw_source_polarisation(layout, settings, target):
    """The polarisation settings of a light or an emission (properties.PolarSourceSettings)."""
    layout.use_property_split = True
    layout.prop(settings, "polarisation")
    if settings.polarisation != "NONE":
        layout.prop(settings, "degree")
        if settings.polarisation == "LINEAR":
            layout.prop(settings, "angle")
        else:
            layout.prop(settings, "handedness")
    layout.operator("polar.lcd_screen_preset", icon="PRESET").target = target


class _OwnerPanel(_PolarPanel):
    """A panel of the Properties editor's tab of one data block: ``owner`` names it in the context
    ("light", "material", "world"); the panel shows when the engine is Polar and that block exists."""
    owner = ""

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, cls.owner, None) is not None


class _SourcePolarisationPanel(_OwnerPanel):
    def draw(self, context):
        draw_source_polarisation(self.layout, getattr(context, self.owner).polar, self.owner.upper())


class POLAR_PT_light_polarisation(_SourcePolarisationPanel, bpy.types.Panel):
    bl_label = "Polarisation"
    bl_context = "data"
    owner = "light"


class POLAR_PT_emission_polarisation(_SourcePolarisationPanel, bpy.types.Panel):
    bl_label = "Emission Polarisation"
    bl_context = "material"
    bl_options = {"DEFAULT_CLOSED"}
    owner = "material"


class POLAR_PT_sky_polarisation(_OwnerPanel, bpy.types.Panel):
    bl_label = "Sky Polarisation"
    bl_context = "world"
    owner = "world"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.world.polar, "sky_polarisation", text="Sky Texture")


classes = (POLAR_PT_sampling, POLAR_PT_light_model, POLAR_PT_polariser, POLAR_PT_performance, POLAR_PT_passes,
           POLAR_PT_data_passes,
           POLAR_PT_light_polarisation, POLAR_PT_emission_polarisation, POLAR_PT_sky_polarisation)

register, unregister = bpy.utils.register_classes_factory(classes)
