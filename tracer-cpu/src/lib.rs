//! The CPU tracer (DESIGN.md sections 6-7). Not written yet: it is the subject of issue 3.
//! Nothing here renders; the crate exists so that the workspace has the layout of DESIGN.md.
