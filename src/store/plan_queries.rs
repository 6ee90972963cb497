// The pose plans' queries (`POST /plans`), written once and compiled for
// each backend like queries.rs: `include!`d by `sqlite.rs` and
// `postgres.rs` after it, with their `Db`, `Backend` and `db_now_ms!`.

macro_rules! plan_cols {
    () => {
        "id, model_id, robot_id, rig_id, options, state, error, error_field, result, runner, \
         lease_until_ms, created_by, created_at, updated_at, started_at, finished_at"
    };
}

impl Backend {
    pub async fn create_plan(&self, p: &super::NewPlan, lease_ms: i64) -> Result<super::PlanRec> {
        let now = now_rfc3339();
        Ok(sqlx::query_as::<_, super::PlanRec>(concat!(
            "INSERT INTO plans (model_id, robot_id, rig_id, options, state, runner, lease_until_ms, \
             created_by, created_at, updated_at) VALUES ($1, $2, $3, $4, 'queued', $5, ",
            db_now_ms!(),
            " + $6, $7, $8, $8) RETURNING ",
            plan_cols!()
        ))
        .bind(p.model_id)
        .bind(p.robot_id)
        .bind(p.rig_id)
        .bind(&p.options)
        .bind(&p.runner)
        .bind(lease_ms)
        .bind(&p.created_by)
        .bind(now)
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn get_plan(&self, id: i64) -> Result<super::PlanRec> {
        // A plan whose runner stopped renewing its lease will not finish:
        // say so before answering (on the database's clock).
        let now = now_rfc3339();
        sqlx::query(concat!(
            "UPDATE plans SET state = 'failed', error = $2, runner = NULL, lease_until_ms = NULL, \
             finished_at = $3, updated_at = $3 \
             WHERE id = $1 AND state IN ('queued', 'running') AND lease_until_ms < ",
            db_now_ms!()
        ))
        .bind(id)
        .bind(super::PLAN_INTERRUPTED)
        .bind(&now)
        .execute(&self.pool)
        .await?;
        sqlx::query_as::<_, super::PlanRec>(concat!(
            "SELECT ",
            plan_cols!(),
            " FROM plans WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .ok_or(StoreError::NotFound { what: "plan", id })
    }

    pub async fn count_queued_plans(&self) -> Result<i64> {
        Ok(sqlx::query_scalar::<_, i64>(concat!(
            "SELECT COUNT(*) FROM plans WHERE state = 'queued' AND lease_until_ms >= ",
            db_now_ms!()
        ))
        .fetch_one(&self.pool)
        .await?)
    }

    pub async fn renew_plan(&self, id: i64, runner: &str, lease_ms: i64) -> Result<bool> {
        let r = sqlx::query(concat!(
            "UPDATE plans SET lease_until_ms = ",
            db_now_ms!(),
            " + $3 WHERE id = $1 AND runner = $2 AND state IN ('queued', 'running')"
        ))
        .bind(id)
        .bind(runner)
        .bind(lease_ms)
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected() == 1)
    }

    pub async fn start_plan(&self, id: i64, runner: &str, lease_ms: i64) -> Result<bool> {
        let now = now_rfc3339();
        let r = sqlx::query(concat!(
            "UPDATE plans SET state = 'running', started_at = $3, updated_at = $3, lease_until_ms = ",
            db_now_ms!(),
            " + $4 WHERE id = $1 AND runner = $2 AND state = 'queued'"
        ))
        .bind(id)
        .bind(runner)
        .bind(&now)
        .bind(lease_ms)
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected() == 1)
    }

    pub async fn finish_plan(&self, id: i64, runner: &str, end: &super::PlanEnd) -> Result<bool> {
        let (state, result, error, field) = match end {
            super::PlanEnd::Succeeded { plan_json } => ("succeeded", Some(plan_json.as_str()), None, None),
            super::PlanEnd::Failed { error, field } => ("failed", None, Some(error.as_str()), field.as_deref()),
        };
        let r = sqlx::query(
            "UPDATE plans SET state = $3, result = $4, error = $5, error_field = $6, runner = NULL, \
             lease_until_ms = NULL, finished_at = $7, updated_at = $7 \
             WHERE id = $1 AND runner = $2 AND state IN ('queued', 'running')",
        )
        .bind(id)
        .bind(runner)
        .bind(state)
        .bind(result)
        .bind(error)
        .bind(field)
        .bind(now_rfc3339())
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected() == 1)
    }
}
