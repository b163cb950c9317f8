//! The Vulkan compute tracer (DESIGN.md section 6). Not written yet: it is the subject of issues 4
//! and 5. Nothing here renders; the crate exists so that the workspace has the layout of DESIGN.md.
