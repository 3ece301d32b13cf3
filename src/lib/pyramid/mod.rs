//! The max-Z / average-colour hierarchy with shadows and shading (`dbms pyramid`).
